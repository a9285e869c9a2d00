"""The interval rules in plain numpy: slow, simple, and what the numba interpreter
(:mod:`surfgen.generator.eval.intervals`) is tested against.

The program is interpreted op by op in Python, each op on numpy arrays over all K boxes
(an interval is three arrays ``lo``, ``hi``, ``nan``; ``lo > hi`` is the empty interval:
every value NaN). Each rule is the simplest sound one: the function at the ends of the
interval and at the critical points that may lie inside it (their values known exactly),
corners for the operations monotone in each operand, the whole range where a pole or a jump
may lie inside. It widens the elementary functions' values more than the numba rules do
(8 ulp against 4, a larger slack near critical points), so the contract tested is: both are
sound, and the numba bounds lie inside these.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from surfgen.generator import elementary as E
from surfgen.generator.eval.compiler import Program
from surfgen.generator.eval.intervals import check_boxes, finish
from surfgen.generator.eval.opcodes import LEVEL_ORDER, M_S, M_SV, M_V, M_VS, OPNAMES
from surfgen.generator.formula import constituents as cf
from surfgen.generator.formula import logic

INF = np.inf
PI = np.pi
HALF = np.pi / 2
REL = 2.0**-48  # >= 8 ulp
TINY = 2.0**-1050
RT_ABS = 1e-26
SLACK = 1e-9  # periods: a critical point this close to the interval counts as inside
HUGE = 2.0**50

Iv = tuple[np.ndarray, np.ndarray, np.ndarray]  # lo, hi, nan


def _up(v: np.ndarray, extra: float = 0.0) -> np.ndarray:
    with np.errstate(all="ignore"):
        w = v + np.abs(v) * REL + TINY + extra
    return np.where(np.isfinite(v), w, v)


def _down(v: np.ndarray, extra: float = 0.0) -> np.ndarray:
    with np.errstate(all="ignore"):
        w = v - np.abs(v) * REL - TINY - extra
    return np.where(np.isfinite(v), w, v)


def _hits(lo: np.ndarray, hi: np.ndarray, off: float, per: float) -> np.ndarray:
    """Whether some ``off + j per`` may lie in ``[lo, hi]`` (True when in doubt)."""
    with np.errstate(all="ignore"):
        t0 = (lo - off) / per
        t1 = (hi - off) / per
        s = SLACK * (1.0 + np.maximum(np.abs(t0), np.abs(t1)))
        hit = np.floor(t1 + s) >= np.ceil(t0 - s)
    far = ~((np.abs(lo) <= HUGE) & (np.abs(hi) <= HUGE))
    return far | (hi - lo >= per) | hit


def _f(name: str) -> Callable[[np.ndarray], np.ndarray]:
    if name in E.ROUND_TRIPS:
        return lambda u: E.round_trip(name, u)
    if name in ("sec", "csc", "cot"):
        return {"sec": cf.sec, "csc": cf.csc, "cot": cf.cot}[name]
    return lambda u: E.call(name, u)


def _empty_where(out: Iv, mask: np.ndarray) -> Iv:
    lo, hi, nan = out
    return np.where(mask, INF, lo), np.where(mask, -INF, hi), nan | mask


# ----------------------------------------------------------------------------- unary rules

MONOTONE = {  # name: (domain lo, domain hi, increasing)
    "asin": (-1.0, 1.0, True),
    "acos": (-1.0, 1.0, False),
    "atan": (-INF, INF, True),
    "sinh": (-INF, INF, True),
    "tanh": (-INF, INF, True),
    "asinh": (-INF, INF, True),
    "acosh": (1.0, INF, True),
    "atanh": (-1.0, 1.0, True),
    "exp": (-INF, INF, True),
    "log": (0.0, INF, True),
    "log10": (0.0, INF, True),
    "cbrt": (-INF, INF, True),
}
WAVES = {  # name: (where its maxima are, mod 2 pi; its minima; min value; max value)
    "sin": (HALF, -HALF, -1.0, 1.0),
    "cos": (0.0, PI, -1.0, 1.0),
    "asinsin": (HALF, -HALF, -HALF, HALF),
    "acoscos": (PI, 0.0, 0.0, PI),
}
JUMPS = {  # name: (where its poles or jumps are, mod pi; range; increasing)
    "tan": (HALF, -INF, INF, True),
    "cot": (0.0, -INF, INF, False),
    "atantan": (HALF, -HALF, HALF, True),
    "acotcot": (0.0, 0.0, PI, True),
}


def _monotone(name: str, a: Iv) -> Iv:
    lo, hi, nan = a
    dlo, dhi, inc = MONOTONE[name]
    f = _f(name)
    v0 = f(np.clip(lo, dlo, dhi))
    v1 = f(np.clip(hi, dlo, dhi))
    if not inc:
        v0, v1 = v1, v0
    out = (_down(v0), _up(v1), nan | (lo < dlo) | (hi > dhi))
    return _empty_where(out, (lo > dhi) | (hi < dlo))


def _wave(name: str, a: Iv) -> Iv:
    lo, hi, nan = a
    at_max, at_min, vmin, vmax = WAVES[name]
    extra = RT_ABS if name in E.ROUND_TRIPS else 0.0
    f = _f(name)
    v0, v1 = f(lo), f(hi)
    olo = _down(np.minimum(v0, v1), extra)
    ohi = _up(np.maximum(v0, v1), extra)
    olo = np.where(_hits(lo, hi, at_min, 2 * PI), _down(np.float64(vmin), extra), olo)
    ohi = np.where(_hits(lo, hi, at_max, 2 * PI), _up(np.float64(vmax), extra), ohi)
    return olo, ohi, nan | ~np.isfinite(lo) | ~np.isfinite(hi)


def _jumps(name: str, a: Iv) -> Iv:
    lo, hi, nan = a
    at, vmin, vmax, inc = JUMPS[name]
    extra = RT_ABS if name in E.ROUND_TRIPS else 0.0
    f = _f(name)
    v0, v1 = f(lo), f(hi)
    if not inc:
        v0, v1 = v1, v0
    jump = _hits(lo, hi, at, PI)
    olo = np.where(jump, _down(np.float64(vmin), extra), _down(v0, extra))
    ohi = np.where(jump, _up(np.float64(vmax), extra), _up(v1, extra))
    return olo, ohi, nan | ~np.isfinite(lo) | ~np.isfinite(hi)


def _reciprocal(a: Iv) -> Iv:
    lo, hi, nan = a
    zero = (lo <= 0) & (hi >= 0)
    with np.errstate(all="ignore"):
        return np.where(zero, -INF, 1.0 / hi), np.where(zero, INF, 1.0 / lo), nan


def _even(lo: np.ndarray, hi: np.ndarray, f0: np.ndarray, f1: np.ndarray, at0: float):
    """A function even about 0, increasing in |u|, worth ``at0`` at 0."""
    zero = (lo <= 0) & (hi >= 0)
    return np.where(zero, at0, np.minimum(f0, f1)), np.maximum(f0, f1)


def _unary(name: str, a: Iv, consts: np.ndarray, imm: int) -> Iv:
    lo, hi, nan = a
    if name == "copy":
        return a
    if name == "neg":
        return -hi, -lo, nan
    if name in ("abs", "square"):
        f = np.abs if name == "abs" else np.square
        o0, o1 = _even(lo, hi, f(lo), f(hi), 0.0)
        return o0, o1, nan
    if name == "recip":
        return _reciprocal(a)
    if name == "sqrt":
        out = (np.sqrt(np.maximum(lo, 0.0)), np.sqrt(np.maximum(hi, 0.0)), nan | (lo < 0))
        return _empty_where(out, hi < 0)
    if name in ("sign", "floor", "ceil", "trunc"):
        f = {"sign": np.sign, "floor": np.floor, "ceil": np.ceil, "trunc": np.trunc}[name]
        return f(lo), f(hi), nan
    if name == "usign":
        return cf.unit_sign(lo), cf.unit_sign(hi), nan
    if name == "not":
        return _bool(_can_false(a), _can_true(a))
    if name in MONOTONE:
        return _monotone(name, a)
    if name in WAVES:
        return _wave(name, a)
    if name in JUMPS:
        return _jumps(name, a)
    if name in ("sec", "csc"):
        return _reciprocal(_wave("cos" if name == "sec" else "sin", a))
    if name == "cosh":
        f0, f1 = E.call("cosh", lo), E.call("cosh", hi)
        o0, o1 = _even(lo, hi, f0, f1, 1.0)
        return _down(o0), _up(o1), nan
    if name == "powi":
        e = np.full_like(lo, float(imm))
        return _pow(a, (e, e, np.zeros_like(nan)))
    if name == "series":
        return _series(a, consts, imm)
    if name == "segsum":
        return _segsum(a, consts, imm)
    raise AssertionError(f"no interval rule for {name}")  # pragma: no cover


def _series(a: Iv, consts: np.ndarray, base: int) -> Iv:
    """0 outside the segments, else ``2 (x - r(i-1))`` in [0, 2r] (a little more: rounding);
    exactly that on a box inside one segment."""
    lo, hi, nan = a
    r, p, exact = consts[base], consts[base + 1], consts[base + 2]
    nan = nan | ~(np.maximum(np.abs(lo), np.abs(hi)) <= 1e307)
    if exact:
        return np.full_like(lo, -INF), np.full_like(hi, INF), np.ones_like(nan)
    top = _up(np.float64(2 * r + 4 * abs(r * (p + 1)) * 2.0**-52))
    olo = np.zeros_like(lo)
    ohi = np.full_like(hi, top)
    with np.errstate(all="ignore"):
        i = np.floor(lo / r) + 1.0
        for j in (i - 1.0, i, i + 1.0):
            a0, b0 = r * (j - 1.0), r * j
            one = (-p <= j) & (j <= p) & (a0 <= lo) & (lo < b0) & (hi < b0) & ~nan
            olo = np.where(one, 0.0 + 2.0 * (lo - a0), olo)
            ohi = np.where(one, 0.0 + 2.0 * (hi - a0), ohi)
    outside = (hi < r * (-p - 1.0)) | (lo >= r * p)
    return np.where(outside, 0.0, olo), np.where(outside, 0.0, ohi), nan


def _segsum(a: Iv, consts: np.ndarray, base: int) -> Iv:
    lo, hi, nan = a
    kind, nseg = consts[base], int(consts[base + 1])
    segs = [consts[base + 2 + 6 * s : base + 8 + 6 * s] for s in range(nseg)]

    def line(c, x):
        with np.errstate(all="ignore"):
            if kind == 0.0:
                return (c[2] * x + c[3] - c[4]) / c[5]
            return c[2] * x + c[3]

    olo = np.full_like(lo, INF)
    ohi = np.full_like(hi, -INF)
    contiguous = all(s[1] == t[0] for s, t in zip(segs, segs[1:], strict=False))
    zero = (lo < segs[0][0]) | (hi >= segs[-1][1]) | (not contiguous)
    olo, ohi = np.where(zero, 0.0, olo), np.where(zero, 0.0, ohi)
    for c in segs:
        nan = nan | ~np.isfinite(line(c, lo)) | ~np.isfinite(line(c, hi))
        x0, x1 = np.maximum(lo, c[0]), np.minimum(hi, c[1])
        meets = (lo < c[1]) & (hi >= c[0])
        w0 = 0.5 * (0.0 + 2.0 * line(c, x0))
        w1 = 0.5 * (0.0 + 2.0 * line(c, x1))
        olo = np.where(meets, np.fmin(olo, np.fmin(w0, w1)), olo)
        ohi = np.where(meets, np.fmax(ohi, np.fmax(w0, w1)), ohi)
    return olo, ohi, nan


# ----------------------------------------------------------------------------- binary rules


def _corners(f, a: Iv, b: Iv, zero_at_nan: bool) -> Iv:
    with np.errstate(all="ignore"):
        c = np.stack([f(a[0], b[0]), f(a[0], b[1]), f(a[1], b[0]), f(a[1], b[1])])
    bad = np.isnan(c).any(axis=0)
    if zero_at_nan and f is np.multiply:  # 0 * inf with 0 inside an operand
        bad |= (_has0(a) & _has_inf(b)) | (_has0(b) & _has_inf(a))
    lo = np.where(np.isnan(c), INF, c).min(axis=0)
    hi = np.where(np.isnan(c), -INF, c).max(axis=0)
    if zero_at_nan:  # 0 * inf, inf / inf: the finite neighbours give 0
        lo, hi = np.where(bad, np.minimum(lo, 0.0), lo), np.where(bad, np.maximum(hi, 0.0), hi)
    return lo, hi, a[2] | b[2] | bad


def _has0(v: Iv) -> np.ndarray:
    return (v[0] <= 0) & (v[1] >= 0)


def _has_inf(v: Iv) -> np.ndarray:
    return ~np.isfinite(v[0]) | ~np.isfinite(v[1])


def _div(a: Iv, b: Iv, ratio: bool) -> Iv:
    lo, hi, nan = _corners(np.divide, a, b, True)
    z = _has0(b)
    lo, hi = np.where(z, -INF, lo), np.where(z, INF, hi)
    zz = _has0(a) & z
    nan = nan | (_has_inf(a) & _has_inf(b))
    if ratio:  # 0/0 is 1
        return np.where(zz, np.minimum(lo, 1.0), lo), np.where(zz, np.maximum(hi, 1.0), hi), nan
    return lo, hi, nan | zz


def _can_true(v: Iv) -> np.ndarray:
    return (v[0] <= v[1]) & ((v[0] <= -0.5) | (v[1] >= 0.5))


def _can_false(v: Iv) -> np.ndarray:
    return v[2] | ((v[0] <= v[1]) & (v[0] < 0.5) & (v[1] > -0.5))


def _bool(t: np.ndarray, f: np.ndarray) -> Iv:
    lo = np.where(f, 0.0, np.where(t, 1.0, INF))
    hi = np.where(t, 1.0, np.where(f, 0.0, -INF))
    return lo, hi, np.zeros(lo.shape, bool)


def _compare(name: str, a: Iv, b: Iv) -> Iv:
    """Whether the 0/1 result can be 1 (some pair of values passes) and can be 0."""
    nan = a[2] | b[2]
    empty = (a[0] > a[1]) | (b[0] > b[1])
    eps = logic.EPS
    if name == "lt":
        t, f = a[0] < b[1] - eps, nan | (a[1] >= b[0] - eps)
    elif name == "le":
        t, f = a[0] <= b[1] + eps, nan | (a[1] > b[0] + eps)
    else:
        dlo, dhi, dnan = _corners(np.subtract, a, b, False)
        mlo = np.where((dlo <= 0) & (dhi >= 0), 0.0, np.minimum(np.abs(dlo), np.abs(dhi)))
        mhi = np.maximum(np.abs(dlo), np.abs(dhi))
        some = dlo <= dhi
        if name == "eq":
            t, f = some & (mlo <= eps), dnan | (mhi > eps)
        else:
            t, f = some & (mhi > eps), dnan | (mlo <= eps)
    return _bool(t & ~empty, f | empty)


def _fmod(a: Iv, b: Iv) -> Iv:
    """|fmod(a, b)| < |b| and <= |a|, the sign of a; exact on a piece without a wrap."""
    lo, hi = a[0], a[1]
    m = np.maximum(np.abs(b[0]), np.abs(b[1]))
    olo = np.where(lo >= 0, 0.0, np.maximum(lo, -m))
    ohi = np.where(hi <= 0, 0.0, np.minimum(hi, m))
    with np.errstate(all="ignore"):
        r0, r1 = np.fmod(lo, b[0]), np.fmod(hi, b[0])
        one = (b[0] == b[1]) & ~b[2] & (b[0] != 0) & ((lo >= 0) | (hi <= 0)) & (hi - lo < m)
    one &= (r1 >= r0) & ~_has_inf(a) & np.isfinite(b[0])
    nan = a[2] | b[2] | _has0(b) | _has_inf(a)
    return np.where(one, r0, olo), np.where(one, r1, ohi), nan


def _pow(a: Iv, b: Iv) -> Iv:
    lo, hi, an = a
    e = b[0]
    const = (b[0] == b[1]) & ~b[2]
    out_lo = np.full_like(lo, -INF)
    out_hi = np.full_like(hi, INF)
    nan = np.ones_like(an)
    # a non-negative base (corners: monotone in each operand; pow(-0, -odd) = -inf)
    pos = lo >= 0
    c_lo, c_hi, c_nan = _corners(E.power, a, b, False)
    c_lo = np.where((lo == 0) & (b[0] < 0), -INF, _down(c_lo))
    c_hi = _up(c_hi)
    out_lo, out_hi = np.where(pos, c_lo, out_lo), np.where(pos, c_hi, out_hi)
    nan = np.where(pos, c_nan, nan)
    # a constant exponent: each sign of the base apart (a non-integer one: NaN below 0)
    with np.errstate(all="ignore"):
        integer = np.isfinite(e) & (np.floor(e) == e)
        neg = np.minimum(hi, -0.0)
        p_neg = np.stack([E.power(lo, e), E.power(neg, e)])
        p_pos = np.stack([E.power(np.maximum(lo, 0.0), e), E.power(np.maximum(hi, 0.0), e)])
    has_neg, has_pos = lo < 0, hi >= 0
    at0 = np.where(e > 0, 0.0, np.where(e < 0, INF, 1.0))
    neg_odd = integer & (np.fmod(e, 2.0) != 0) & (e < 0) & (lo <= 0) & (hi >= 0)
    vals = np.concatenate([np.where(integer & has_neg, p_neg, np.nan),
                           np.where(has_pos, p_pos, np.nan),
                           np.where((lo <= 0) & (hi >= 0), at0, np.nan)[None],
                           np.where(neg_odd | ((lo == -INF) & ~integer), -INF, np.nan)[None],
                           np.where(neg_odd | ((lo == -INF) & ~integer), INF, np.nan)[None]])  # fmt: skip
    k_lo = _down(np.nanmin(np.where(np.isnan(vals), INF, vals), axis=0))
    k_hi = _up(np.nanmax(np.where(np.isnan(vals), -INF, vals), axis=0))
    k_nan = an | (~integer & has_neg)
    fine = const & np.isfinite(e)
    out_lo, out_hi = np.where(fine, k_lo, out_lo), np.where(fine, k_hi, out_hi)
    nan = np.where(fine, k_nan, nan)
    one = np.ones_like(lo)
    out_lo = np.where(const & (e == 0), one, out_lo)  # the x^c convention: u^0 = 1
    out_hi = np.where(const & (e == 0), one, out_hi)
    nan = np.where(const & (e == 0), False, nan)
    special = const & ~np.isfinite(e)
    out_lo, out_hi = np.where(special, 0.0, out_lo), np.where(special, INF, out_hi)
    nan = np.where(special, an, nan)
    # NaN anywhere: pow(NaN, 0) = pow(1, NaN) = 1
    anyn = (an | b[2]) & ~(const & (e == 0))
    out_lo, out_hi = (
        np.where(anyn, np.minimum(out_lo, 1.0), out_lo),
        np.where(anyn, np.maximum(out_hi, 1.0), out_hi),
    )  # noqa: E501
    empty = (lo > hi) | (b[0] > b[1])
    out_lo = np.where(empty & ~(const & (e == 0)), 1.0, out_lo)
    out_hi = np.where(empty & ~(const & (e == 0)), 1.0, out_hi)
    return out_lo, out_hi, nan | (empty & ~(const & (e == 0))) | anyn


def _atan2(a: Iv, b: Iv) -> Iv:
    lo, hi, nan = _corners(lambda y, x: E.call("atan2", y, x), a, b, False)
    ok = (b[0] > 0) | (a[0] > 0) | (a[1] < 0)
    return (
        np.where(ok, _down(lo), _down(np.float64(-PI))),
        np.where(ok, _up(hi), _up(np.float64(PI))),
        nan,
    )  # noqa: E501


def _binary(name: str, a: Iv, b: Iv, same: bool) -> Iv:
    if name in ("add", "sub", "mul"):
        if same and name == "mul":
            return _unary("square", a, np.zeros(0), 0)
        f = {"add": np.add, "sub": np.subtract, "mul": np.multiply}[name]
        return _corners(f, a, b, name == "mul")
    if name in ("div", "ratio1"):
        return _div(a, b, name == "ratio1")
    if name in ("min", "max"):
        f = np.minimum if name == "min" else np.maximum
        return f(a[0], b[0]), f(a[1], b[1]), a[2] | b[2]
    if name in ("lt", "le", "eq", "ne"):
        return _compare(name, a, b)
    if name in ("and", "or"):
        ta, fa, tb, fb = _can_true(a), _can_false(a), _can_true(b), _can_false(b)
        return _bool(ta & tb, fa | fb) if name == "and" else _bool(ta | tb, fa & fb)
    if name in ("pick", "pickn"):
        t, f = _can_true(a), _can_false(a)
        take, zero = (t, f) if name == "pick" else (f, t)
        lo = np.where(take, b[0], INF)
        hi = np.where(take, b[1], -INF)
        return (
            np.where(zero, np.minimum(lo, 0.0), lo),
            np.where(zero, np.maximum(hi, 0.0), hi),
            take & b[2],
        )  # noqa: E501
    if name == "fmod":
        return _fmod(a, b)
    if name == "pow":
        return _pow(a, b)
    if name == "atan2":
        return _atan2(a, b)
    raise AssertionError(f"no interval rule for {name}")  # pragma: no cover


NON_STRICT = {"not", "lt", "le", "eq", "ne", "and", "or", "pick", "pickn", "pow", "powi"}


def apply_op(name: str, args: list[Iv], consts: np.ndarray, imm: int, same: bool = False) -> Iv:
    """The interval of opcode ``name`` of the intervals ``args`` (``same``: both operands are
    one value, as in ``x*x``)."""
    with np.errstate(all="ignore"):  # inf - inf, 0 * inf...: values, not errors
        if len(args) == 1:
            out = _unary(name, args[0], consts, imm)
        else:
            out = _binary(name, args[0], args[1], same)
    lo, hi, nan = (np.asarray(v) for v in out)
    out = (lo.astype(np.float64), hi.astype(np.float64), nan.astype(bool))
    if name not in NON_STRICT:  # a NaN operand everywhere: NaN everywhere
        empty = np.zeros(lo.shape, bool)
        for v in args:
            empty |= v[0] > v[1]
        out = _empty_where(out, empty)
    return out


# ----------------------------------------------------------------------------- the tape


def _const(v: float, K: int) -> Iv:
    if np.isnan(v):
        return np.full(K, INF), np.full(K, -INF), np.ones(K, bool)
    return np.full(K, v), np.full(K, v), np.zeros(K, bool)


def reference_bounds(program: Program, lo: np.ndarray, hi: np.ndarray):
    """:func:`surfgen.generator.eval.intervals.program_bounds`, in numpy, op by op."""
    blo, bhi = check_boxes(lo, hi)
    K = blo.shape[0]
    store: dict[tuple[int, int], Iv] = {}
    for axis, kind in enumerate((1, 2, 4)):
        store[(kind, 0)] = (blo[:, axis].copy(), bhi[:, axis].copy(), np.zeros(K, bool))
    out: Iv = _const(np.nan, K)
    for lv in LEVEL_ORDER:
        c0, c1, l0, l1, s0, s1 = (int(v) for v in program.blocks[lv])
        if c0 == c1:
            continue
        W: dict[int, Iv] = {}
        S: dict[int, Iv] = {}
        for kind, row, slot, vec in program.loads[l0:l1]:
            v = _const(program.consts[row], K) if kind == 0 else store[(int(kind), int(row))]
            (W if vec else S)[int(slot)] = v
        for op, mode, d, a, b, imm in program.code[c0:c1]:
            name = OPNAMES[int(op)]
            if mode == M_V:
                args, same = [W[int(a)]], False
            elif mode == M_S:
                args, same = [S[int(a)]], False
            elif mode == M_VS:
                args, same = [W[int(a)], S[int(b)]], False
            elif mode == M_SV:
                args, same = [S[int(a)], W[int(b)]], False
            else:
                args, same = [W[int(a)], W[int(b)]], a == b
            W[int(d)] = apply_op(name, args, program.consts, int(imm), bool(same))
        for slot, kind, row in program.stores[s0:s1]:
            if kind == 7:
                out = W[int(slot)]
            else:
                store[(int(kind), int(row))] = W[int(slot)]
    return finish(out[0], out[1], out[2].astype(np.uint8))


__all__ = ["apply_op", "reference_bounds"]
