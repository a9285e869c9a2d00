"""The interval rule of every opcode against dense sampling: each rule (numba,
:mod:`surfgen.generator.eval.interval_kernels`) runs on many input intervals and its bounds are
compared with the fast evaluator's values (the compiled interpreter, one code row) at points of
those intervals: the ends, their neighbours, the critical points inside, random points. A
mutation test narrows each rule a little and checks that the comparison then fails."""

from __future__ import annotations

import ctypes
import functools
import math
from dataclasses import dataclass

import numpy as np
import pytest

from surfgen.generator.eval import interpreter
from surfgen.generator.eval.compiler import compile_tree
from surfgen.generator.eval.interval_kernels import run_code_iv
from surfgen.generator.eval.intervals_reference import apply_op
from surfgen.generator.eval.opcodes import ARITY, M_V, M_VV, OP, OPCODES
from surfgen.generator.formula.parser import parse

INF = math.inf
Interval = tuple[float, float, bool]  # lo, hi, may be NaN; lo > hi: every value NaN
EMPTY: Interval = (INF, -INF, True)

SPECIAL: list[Interval] = [
    (0.0, 0.0, False), (-0.0, 0.0, False), (-0.0, -0.0, False), (-1.0, 1.0, False),
    (0.0, 1.0, False), (-1.0, 0.0, False), (0.5, 0.5, False), (-0.5, 0.5, False),
    (1.0, INF, False), (-INF, -1.0, False), (-INF, INF, False), (0.0, INF, False),
    (-INF, 0.0, False), (INF, INF, False), (-INF, -INF, False), (1e-300, 1e-290, False),
    (-2.0, 3.0, False), (1e300, 1.7e308, False), (1.4, 1.7, False), (3.1, 3.2, False),
    (-4.8, -3.1, False), (1.0, 1.0, False), (-1.0, -1.0, False), (2.0, 2.0, False),
    (0.3, 0.9, False), (-0.9, -0.3, False), (0.49, 0.51, False), (-3.0, -2.0, False),
    (1e15, 1e16, False), (-1e20, 1e20, False), (0.0, 1.0, True), (-2.0, 2.0, True), EMPTY,
]  # fmt: skip


def random_intervals(rng: np.random.Generator, n: int) -> list[Interval]:
    """Intervals of every scale, points among them, some that may be NaN, some empty."""
    out: list[Interval] = []
    for _ in range(n):
        scale = rng.choice([2.0, 8.0, 60.0, 1e4])
        c = float(rng.uniform(-scale, scale))
        if rng.random() < 0.1:
            c = float(np.sign(rng.normal()) * 10.0 ** rng.uniform(-12, 12))
        w = 0.0 if rng.random() < 0.15 else float(10.0 ** rng.uniform(-12, 1.2))
        nan = bool(rng.random() < 0.1)
        out.append((c - w, c + w, nan))
    return out


def samples(iv: Interval, rng: np.random.Generator, m: int = 40) -> np.ndarray:
    """Points of ``iv``: its ends and their inner neighbours, the critical points of the
    functions (multiples of pi/2, 0, ±0.5, ±1) inside, random points; NaN when it may be."""
    lo, hi, nan = iv
    if lo > hi:
        return np.array([np.nan])
    pts = [lo, hi, np.nextafter(lo, hi), np.nextafter(hi, lo)]
    flo = max(lo, -1e300)
    fhi = min(hi, 1e300)
    if flo <= fhi:
        pts += list(rng.uniform(flo, fhi, m)) if fhi - flo < 1e300 else []
        pts += [flo, fhi, (flo + fhi) / 2]
        for v in (0.0, -0.0, 0.5, -0.5, 1.0, -1.0, 1e-300, -1e-300, 1e10, -1e10):
            if flo <= v <= fhi:
                pts.append(v)
        if abs(flo) < 1e6 and abs(fhi) < 1e6:  # the extrema and poles of the periodic ones
            for k in range(
                int(np.floor(flo / (np.pi / 2))) - 1, int(np.ceil(fhi / (np.pi / 2))) + 2
            ):
                c = k * (np.pi / 2)
                for v in (c, np.nextafter(c, INF), np.nextafter(c, -INF)):
                    if flo <= v <= fhi:
                        pts.append(v)
                if len(pts) > 4 * m:
                    break
    if nan:
        pts.append(np.nan)
    return np.array(pts, dtype=np.float64)


# ----------------------------------------------------------------------------- one operation


def point_values(op: str, a: np.ndarray, b: np.ndarray, consts: np.ndarray, imm: int) -> np.ndarray:
    """The fast evaluator's values of opcode ``op`` at the points ``a`` (and ``b``): one code
    row run by the compiled interpreter itself."""
    n = a.size
    W = np.zeros((3, max(n, 1)))
    W[0, :n] = a
    W[1, :n] = b
    mode = M_V if ARITY[op] == 1 else M_VV
    code = np.array([[OP[op], mode, 2, 0, 1, imm]], dtype=np.int64)
    consts = np.ascontiguousarray(consts, dtype=np.float64)
    S = np.zeros(1)
    T = np.zeros((2, W.shape[1]))
    prof = np.zeros(1)
    fn = interpreter.load_interpreter()
    p = ctypes.c_void_p
    fn.ctypes(
        p(code.ctypes.data), 1, 0, 1, p(consts.ctypes.data), consts.size,
        p(W.ctypes.data), 3, W.shape[1], p(S.ctypes.data), 1, p(T.ctypes.data), T.shape[1],
        n, p(prof.ctypes.data), 0,
    )  # fmt: skip
    return W[2, :n].copy()


def interval_values(
    op: str, a: list[Interval], b: list[Interval], consts: np.ndarray, imm: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The numba rule of ``op`` on the intervals ``a[k]`` (and ``b[k]``): lo, hi, nan."""
    n = len(a)
    L = np.zeros((3, n))
    H = np.zeros((3, n))
    N = np.zeros((3, n), dtype=np.uint8)
    for row, ivs in ((0, a), (1, b)):
        for k, (lo, hi, nan) in enumerate(ivs):
            L[row, k], H[row, k], N[row, k] = lo, hi, nan
    mode = M_V if ARITY[op] == 1 else M_VV
    code = np.array([[OP[op], mode, 2, 0, 1, imm]], dtype=np.int64)
    T = np.zeros((8, n))
    interpreter.load_interpreter()
    run_code_iv(code, 0, 1, np.ascontiguousarray(consts, dtype=np.float64), L, H, N, T, n)
    return L[2].copy(), H[2].copy(), N[2].astype(bool)


@dataclass
class Sampled:
    """One group of cases of an opcode: its inputs, the fast evaluator's values at the samples
    of each input interval (``pa``, ``pb``, ``v`` per case) and the rule's bounds."""

    op: str
    a: list[Interval]
    b: list[Interval]
    consts: np.ndarray
    imm: int
    points: list[tuple[np.ndarray, np.ndarray, np.ndarray]]

    def bounds(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return interval_values(self.op, self.a, self.b, self.consts, self.imm)


def sample_group(op, a_ivs, b_ivs, consts, imm, rng, m=40) -> Sampled:
    points = []
    for k, ia in enumerate(a_ivs):
        sa = samples(ia, rng, m)
        if ARITY[op] == 2:
            sb = samples(b_ivs[k], rng, m // 2)
            ga, gb = np.meshgrid(sa, sb, indexing="ij")
            pa, pb = ga.ravel(), gb.ravel()
        else:
            pa, pb = sa, np.zeros_like(sa)
        points.append((pa, pb, point_values(op, pa, pb, consts, imm)))
    return Sampled(op, a_ivs, b_ivs, consts, imm, points)


def violations(group: Sampled, bounds) -> list[str]:
    """Where the fast evaluator's value at a sample of the inputs is not NaN and out of the
    bounds, or NaN where the bounds say it cannot be."""
    lo, hi, nan = bounds
    bad: list[str] = []
    for k, (pa, pb, v) in enumerate(group.points):
        where = f"{group.op}{group.a[k]}{group.b[k] if group.b else ''}"
        out = ~np.isnan(v) & ((v < lo[k]) | (v > hi[k]))
        if out.any():
            j = int(np.argmax(out))
            bad.append(f"{where}: f({pa[j]!r}, {pb[j]!r}) = {v[j]!r} not in [{lo[k]!r}, {hi[k]!r}]")
        if not nan[k] and np.isnan(v).any():
            j = int(np.argmax(np.isnan(v)))
            bad.append(f"{where}: f({pa[j]!r}, {pb[j]!r}) is NaN, the rule says it cannot be")
    return bad


# ----------------------------------------------------------------------------- cases per opcode


def _op_params(formula: str, op: str) -> tuple[np.ndarray, int]:
    """The constants and immediate of opcode ``op`` in the program of ``formula``."""
    prog = compile_tree(parse(formula))
    for row in prog.code:
        if row[0] == OP[op]:
            return np.array(prog.consts), int(row[5])
    raise AssertionError(f"no {op} in {formula}")


def op_cases(op: str, seed: int = 0) -> list[tuple[list, list, np.ndarray, int]]:
    """Groups of ``(a intervals, b intervals, consts, imm)`` that exercise ``op``."""
    rng = np.random.default_rng(seed)
    base = SPECIAL + random_intervals(rng, 120)
    none = np.zeros(1)
    if op == "series":
        groups = []
        for f in ("saw1(x,0.3,3)", "tri1(x,1.7,0)", "stair1(x,0.25,2,6)"):
            consts, imm = _op_params(f, op)
            r = consts[imm]
            extra = [(r * i + d, r * i + d + w, False) for i in range(-9, 9)
                     for d in (-1e-9, 0.0, 0.3 * r) for w in (0.0, 0.2 * r, 0.9 * r, 3 * r)]  # fmt: skip
            groups.append((base + extra, [], consts, imm))
        return groups
    if op == "segsum":
        groups = []
        for f in ("fcc8(x)", "fcc(x,0,0,1,2,2,-1,3,0.5)", "fcc(x,-1,1e300,1,-1e300)"):
            consts, imm = _op_params(f, op)
            grid = [(float(a), float(a) + w, False) for a in np.arange(-2.0, 11.0, 0.25)
                    for w in (0.0, 0.1, 0.25, 1.0)]  # fmt: skip
            groups.append((base + grid, [], consts, imm))
        return groups
    if op == "powi":
        return [(base, [], none, e) for e in (3, 2, -2, -3, 0, 1, 5)]
    if ARITY[op] == 1:
        return [(base, [], none, 0)]
    b = SPECIAL + random_intervals(rng, 120)
    rng.shuffle(b)
    groups = [(base, b[: len(base)], none, 0)]
    if op in ("pow", "fmod", "div", "ratio1", "atan2", "mul"):
        exps = [2.0, 0.5, -1.0, 1.0, 0.0, 1.5, 3.0, 2.5, -2.0, -3.0, 0.31, -0.5, 4.0, INF, -INF]
        exps += [0.7, -1.5, 1e20, 2.0**53 + 2]
        if op == "fmod":
            exps = [0.3, -0.3, 1.0, 2.5, -7.0, 1e-3, 0.0]
        sub = base[:: max(1, len(base) // 60)]
        for e in exps:
            groups.append((sub, [(e, e, False)] * len(sub), none, 0))
    return groups


@functools.cache
def sampled(op: str) -> tuple[Sampled, ...]:
    """Every group of cases of ``op`` with its samples evaluated (once per test session)."""
    rng = np.random.default_rng(OP[op])
    return tuple(sample_group(op, *case, rng) for case in op_cases(op, seed=OP[op]))


# ----------------------------------------------------------------------------- tests


@pytest.mark.parametrize("op", list(OPCODES))
def test_rule_holds_every_value_at_dense_samples(op: str) -> None:
    """The rule of every opcode bounds the fast evaluator's values at the ends of its input
    intervals, their neighbours, the critical points inside and random points, and says NaN
    is possible wherever a NaN occurs."""
    bad = [msg for group in sampled(op) for msg in violations(group, group.bounds())]
    assert not bad, "\n".join(bad[:10])


def _narrowed(bounds, side: str, amount: float):
    with np.errstate(invalid="ignore"):  # inf - inf where the bounds are infinite (not used)
        return _narrowed_values(bounds, side, amount)


def _narrowed_values(bounds, side: str, amount: float):
    lo, hi, nan = (np.array(v, copy=True) for v in bounds)
    fin = np.isfinite(lo) & np.isfinite(hi) & (lo < hi)
    if side == "lo":
        lo = np.where(fin, lo + amount * np.maximum(1.0, np.abs(lo)), lo)
    elif side == "hi":
        hi = np.where(fin, hi - amount * np.maximum(1.0, np.abs(hi)), hi)
    elif side == "point":  # a degenerate result pushed off its one value
        one = np.isfinite(lo) & (lo == hi)
        lo = np.where(one, lo + amount * np.maximum(1.0, np.abs(lo)), lo)
        hi = np.where(one, hi + amount * np.maximum(1.0, np.abs(hi)), hi)
    else:
        nan = np.zeros_like(nan)
    return lo, hi, nan


NARROW = 1e-7  # far above the rules' widening (a few ulp), far below their looseness tests


@pytest.mark.parametrize("side", ["lo", "hi"])
@pytest.mark.parametrize("op", list(OPCODES))
def test_a_narrowed_rule_is_caught(op: str, side: str) -> None:
    """Mutation test: each rule narrowed by a relative 1e-7 at one end fails the check above
    (the samples reach the bounds: the check can fail)."""
    caught = sum(len(violations(g, _narrowed(g.bounds(), side, NARROW))) for g in sampled(op))
    assert caught > 0


NAN_OPS = [op for op in OPCODES if op not in ("lt", "le", "eq", "ne", "and", "or", "not")]


@pytest.mark.parametrize("op", NAN_OPS)
def test_a_rule_that_forgets_nan_is_caught(op: str) -> None:
    """Mutation test: every rule whose result can be NaN, told that it cannot, fails the check."""
    caught = sum(len(violations(g, _narrowed(g.bounds(), "nan", 0.0))) for g in sampled(op))
    assert caught > 0


@pytest.mark.parametrize("op", list(OPCODES))
def test_numba_rule_lies_within_the_reference_rule(op: str) -> None:
    """The numba rule is at least as tight as the numpy reference's (which the check above
    holds sound too), and says finite wherever it does."""
    for g in sampled(op):
        lo, hi, nan = g.bounds()
        assert not violations(g, (lo, hi, nan))
        a = _arrays(g.a)
        args = [a] if ARITY[op] == 1 else [a, _arrays(g.b)]
        rlo, rhi, rnan = apply_op(op, args, g.consts, g.imm)
        assert not violations(g, (rlo, rhi, rnan)), "the reference is not sound"
        empty = lo > hi
        inside = empty | ((lo >= rlo) & (hi <= rhi))
        assert inside.all(), [(g.a[k], g.b[k] if g.b else None, (lo[k], hi[k]), (rlo[k], rhi[k]))
                              for k in np.flatnonzero(~inside)[:5]]  # fmt: skip
        assert not np.any(nan & ~rnan)


def _arrays(ivs: list[Interval]):
    lo, hi, nan = (np.array(v) for v in zip(*ivs, strict=True))
    return lo.astype(np.float64), hi.astype(np.float64), nan.astype(bool)


def test_comparisons_and_logic_are_never_nan() -> None:
    for op in ("lt", "le", "eq", "ne", "and", "or", "not"):
        for g in sampled(op):
            assert not g.bounds()[2].any()
            assert not any(np.isnan(v).any() for _, _, v in g.points)
