"""Accuracy and speed of surfgen's exp/log/pow family (``generator/elementary/explog.py``).

    nice -n 10 .venv/bin/python -m tools.accuracy_explog            # 10^6 arguments each
    .venv/bin/python -m tools.accuracy_explog --n 20000 --quick     # a smoke run

Accuracy: for every function, n arguments (random over several scales plus each function's
hard ranges, listed in ``arguments``) are evaluated by the numpy twin (checked bit-identical to
the numba row on all of them) and compared with a high-precision reference in two stages:

1. every argument against glibc's 64-bit-mantissa ``long double`` functions (numpy's
   float128 ufuncs: relative error below 2^-61, i.e. within 0.002 ulp of a double);
2. every argument whose error so estimated exceeds 0.45 ulp (and every result within 1e-12
   of the rounding edges to inf and to 0, and a random 2000-argument sample that validates
   stage 1) is recomputed with mpmath at 40 digits in a Pool of 2.

"max ulp" is therefore an mpmath figure; "share > 0.5 ulp" counts the arguments whose mpmath
error exceeds 0.5 ulp (stage 1 cannot hide one: it is never off by more than 0.01 ulp, and the
script prints the largest stage-1/mpmath discrepancy it saw).

Speed (M evaluations per second of the thread's CPU time, so that other processes on a shared
machine count less; rows of 1024 as in the interpreter's tiles; the three columns measured
interleaved in one run, best of 5): our ``NAME_row``, a numba loop calling ``math.NAME``
(C libm), and numpy's ufunc.
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import time

import mpmath as mp
import numpy as np
from numba import njit

from surfgen.generator.elementary import explog as E

LD = np.longdouble
UNARY = ("exp", "log", "log10", "sinh", "cosh", "tanh", "asinh", "acosh", "atanh", "cbrt")
CONST_POW = {"pow1.5": 1.5, "pow3": 3.0}  # pow_row_vs with these exponents: exact products
ROWS = 1024

# ----------------------------------------------------------------------------- arguments


def _scales(rng: np.random.Generator, n: int) -> np.ndarray:
    """Magnitudes log-uniform over the whole double range, both signs."""
    return rng.choice([-1.0, 1.0], n) * np.exp(rng.uniform(-744.0, 709.0, n))


def arguments(name: str, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray | None]:
    """n arguments for ``name``: a quarter over all scales, a quarter in [-2, 2] or the main
    range, half in the hard ranges (for pow: (x, y) pairs)."""
    q = n // 4
    k = rng.integers(-1074, 1024, q).astype(float)
    if name == "pow":
        x = np.concatenate(
            [
                np.exp(rng.uniform(-10, 10, q)),  # moderate
                np.exp(rng.uniform(-744, 709, q)),  # every scale
                1.0 + rng.normal(0, 1e-7, q // 2),  # log x tiny ...
                -np.round(rng.uniform(1, 300, q // 2)),  # negative bases
                np.exp(rng.uniform(0.01, 20, n - 3 * q)),  # near overflow/underflow
            ]
        )
        y = np.concatenate(
            [
                rng.uniform(-40, 40, q),
                rng.uniform(-1, 1, q),
                rng.choice([-1, 1], q // 2) * 10.0 ** rng.uniform(4, 9, q // 2),  # ... y huge
                np.round(rng.uniform(-120, 120, q // 2)),  # integer exponents
                np.empty(n - 3 * q),
            ]
        )
        edge = rng.choice([709.78, -708.4, -745.1], n - 3 * q) + rng.uniform(-1.0, 0.0, n - 3 * q)
        y[3 * q :] = edge / np.log(x[3 * q :])
        return x, y
    if name in CONST_POW:
        # pow with the constant exponents that take the exact-product path: every scale (the
        # general path outside [2^-300, 2^300]), the main range, and hard cases: the edges of
        # the exact path and their neighbours, perfect squares/cubes (exact results), near 1,
        # near overflow and underflow, subnormals, negative bases.
        edges = np.array([2.0**-300, 2.0**300])
        near = np.concatenate(
            [(edges * (1 + rng.uniform(-1e-12, 1e-12, (q // 8, 2)))).ravel(), edges, -edges]
        )
        top = 1024.0 / CONST_POW[name]
        hard = np.concatenate(
            [
                near,
                np.round(rng.uniform(1, 2**26, q // 4)) ** (2 if name == "pow1.5" else 1),
                1.0 + rng.normal(0, 1e-6, q // 4),
                2.0 ** rng.uniform(top - 2, top + 1, q // 8),
                2.0
                ** rng.uniform(-1074 / CONST_POW[name] - 2, -1074 / CONST_POW[name] + 2, q // 8),
                rng.uniform(0, 2.3e-308, q // 8),
                -rng.uniform(0, 4, q // 16),
            ]
        )
        x = np.concatenate([_scales(rng, q), rng.uniform(0.0, 4.0, q), hard])
        x = np.concatenate([x, rng.uniform(0.0, 4.0, max(0, n - x.size))])[:n]
        return x, np.full(x.size, CONST_POW[name])
    every = _scales(rng, q)
    main = rng.uniform(-2.0, 2.0, q)
    hard = {
        "exp": np.concatenate(
            [k * math.log(2), rng.uniform(-745.2, -708.0, q), rng.uniform(700, 709.8, q)]
        ),
        "log": np.concatenate([2.0**k, 1.0 + rng.normal(0, 1e-6, q), rng.uniform(0, 2.3e-308, q)]),
        "log10": np.concatenate(
            [10.0 ** rng.integers(-300, 300, q), 1.0 + rng.normal(0, 1e-6, q), 2.0**k]
        ),
        "sinh": np.concatenate(
            [rng.uniform(-0.6, 0.6, q), rng.uniform(700, 710.5, q), 2.0 ** -np.abs(k)]
        ),
        "cosh": np.concatenate(
            [rng.uniform(-0.6, 0.6, q), rng.uniform(700, 710.5, q), 2.0 ** -np.abs(k)]
        ),
        "tanh": np.concatenate(
            [rng.uniform(0.1, 0.15, q), rng.uniform(0.15, 20, q), 2.0 ** -np.abs(k)]
        ),
        "asinh": np.concatenate(
            [rng.uniform(-1e-3, 1e-3, q), 2.0 ** rng.uniform(20, 40, q), 2.0**k]
        ),
        "acosh": np.concatenate(
            [1 + np.abs(rng.normal(0, 1e-8, q)), 2.0 ** rng.uniform(20, 40, q), 2.0 ** np.abs(k)]
        ),
        "atanh": np.concatenate(
            [1 - np.abs(rng.normal(0, 1e-8, q)), rng.uniform(-1e-3, 1e-3, q), 2.0 ** -np.abs(k)]
        ),
        "cbrt": np.concatenate(
            [np.round(rng.uniform(-1e5, 1e5, q)) ** 3, 2.0**k, rng.uniform(-1e-308, 1e-308, q)]
        ),
    }[name]
    x = np.concatenate([every, main, hard])[:n]
    if name == "acosh":
        x = np.where(x < 1.0, 1.0 + np.abs(x), x)
    if name == "atanh":
        x = np.where(np.abs(x) > 1.0, 1.0 / x, x)
    return x, None


# ----------------------------------------------------------------------------- references

_LD_FUNCS = {
    "exp": np.exp, "log": np.log, "log10": np.log10, "sinh": np.sinh, "cosh": np.cosh,
    "tanh": np.tanh, "asinh": np.arcsinh, "acosh": np.arccosh, "atanh": np.arctanh, "cbrt": np.cbrt,
}  # fmt: skip
_TOP = LD(2.0) ** 1024 * (1 - LD(2.0) ** -54)  # at least this rounds to inf


def _ulps_ld(got: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """|got - ref| in ulps of the double nearest ref (ref in long double)."""
    a = np.abs(ref)
    _, e = np.frexp(a)
    ulp = np.ldexp(LD(1.0), np.maximum(e - 1, -1022) - 52)
    err = np.abs(got.astype(LD) - ref) / ulp
    special = ~np.isfinite(ref) | (a >= _TOP) | (a == 0)
    want = np.where(a >= _TOP, np.sign(ref) * np.inf, ref).astype(np.float64)
    same = (got == want) | (np.isnan(got) & np.isnan(want))
    err[special] = np.where(same[special], 0.0, np.inf)
    err[~np.isfinite(got) & ~special] = np.inf
    return err.astype(np.float64)


def _mp_ref(name: str, x: float, y: float | None):
    v = mp.mpf(x)
    if name == "pow":
        if x < 0 and y != math.floor(y):
            return mp.nan
        return mp.power(v, mp.mpf(y))
    if name == "cbrt":
        return mp.sign(v) * mp.cbrt(abs(v))
    if name in ("log", "log10") and v <= 0:
        return -mp.inf if v == 0 else mp.nan
    if name == "acosh" and v < 1 or name == "atanh" and abs(v) > 1:
        return mp.nan
    if name == "atanh" and abs(v) == 1:
        return mp.inf * mp.sign(v)
    return getattr(mp, name)(v)


def _mp_ulps(job: tuple[str, list[float], list[float] | None, list[float]]) -> list[float]:
    """Errors in ulps against mpmath at 40 digits (run in a worker)."""
    name, xs, ys, gots = job
    mp.mp.dps = 40
    top = mp.mpf(2) ** 1024 * (1 - mp.mpf(2) ** -54)
    out = []
    for i, (x, got) in enumerate(zip(xs, gots, strict=True)):
        ref = _mp_ref(name, x, ys[i] if ys is not None else None)
        if mp.isnan(ref):
            out.append(0.0 if math.isnan(got) else math.inf)
        elif mp.isinf(ref) or abs(ref) >= top:
            out.append(0.0 if got == (math.inf if ref > 0 else -math.inf) else math.inf)
        elif ref == 0 or not math.isfinite(got):
            out.append(0.0 if got == 0 and ref == 0 else math.inf)
        else:
            e = max(int(mp.floor(mp.log(abs(ref), 2))), -1022)
            out.append(float(abs(mp.mpf(got) - ref) / mp.ldexp(1, e - 52)))
    return out


def accuracy(name: str, n: int, pool, rng: np.random.Generator) -> dict:
    x, y = arguments(name, n, rng)
    if name in CONST_POW:
        c = CONST_POW[name]
        got = E.pow_array(x, c)
        W = np.vstack([x, np.zeros_like(x)])
        E.pow_row_vs(W, 1, 0, c, x.size)
        with np.errstate(all="ignore"):
            ref = np.power(x.astype(LD), LD(c))
            ref[(x < 0) & (c != np.floor(c))] = np.nan
    elif name == "pow":
        got = E.pow_array(x, y)
        W = np.vstack([x, y, np.zeros_like(x)])
        E.pow_row_vv(W, 2, 0, 1, x.size)
        with np.errstate(all="ignore"):
            ref = np.power(x.astype(LD), y.astype(LD))
            ref[(x < 0) & (y != np.floor(y))] = np.nan
    else:
        got = getattr(E, f"{name}_array")(x)
        W = np.vstack([x, np.zeros_like(x)])
        getattr(E, f"{name}_row")(W, 1, 0, x.size)
        with np.errstate(all="ignore"):
            ref = _LD_FUNCS[name](x.astype(LD))
    same_bits = bool(np.array_equal(W[-1].view(np.int64), got.view(np.int64)))
    est = _ulps_ld(got, ref)
    # Stage 1 is exact enough everywhere (long double's range is wider, its error 2^-63
    # relative is 2^-11 of a subnormal's ulp) except within a hair of the rounding edges
    # to inf and to 0, which mpmath decides.
    a = np.abs(ref)
    bottom = LD(2.0) ** -1075
    edgy = (np.abs(a / _TOP - 1) < 1e-12) | (np.abs(a / bottom - 1) < 1e-12)
    flagged = np.flatnonzero((est > 0.45) | edgy)
    sample = rng.choice(x.size, min(2000, x.size), replace=False)
    idx = np.unique(np.concatenate([flagged, sample]))
    chunks = np.array_split(idx, 16)
    jobs = [
        (
            "pow" if name in CONST_POW else name,
            x[c].tolist(),
            None if y is None else y[c].tolist(),
            got[c].tolist(),
        )
        for c in chunks
        if c.size
    ]
    exact = np.full(x.size, np.nan)
    for c, errs in zip([c for c in chunks if c.size], pool.map(_mp_ulps, jobs), strict=True):
        exact[c] = errs
    final = np.where(np.isnan(exact), est, exact)
    finite = np.isfinite(est[sample]) & np.isfinite(exact[sample])
    return {
        "n": x.size,
        "max": float(final.max()),
        "share": float(np.mean(final > 0.5)),
        "same_bits": same_bits,
        "checked": int(idx.size),
        "stage1_dev": float(np.max(np.abs(est[sample][finite] - exact[sample][finite]))),
        "worst": (x[int(np.argmax(final))], None if y is None else y[int(np.argmax(final))]),
        "max_exact": (
            float(final[E._NP_GLOBALS["_pow_exact_lane"](x, y)].max())
            if name in CONST_POW
            else None
        ),
    }


# ----------------------------------------------------------------------------- speed


def _libm_loop(name: str):
    """A numba loop calling C's ``math.NAME`` (numba needs the function named in the source)."""
    src = (
        "def loop(W, d, a, n, reps):\n"
        "    for _ in range(reps):\n"
        "        for k in range(n):\n"
        f"            W[d, k] = {'np' if name == 'cbrt' else 'math'}.{name}(W[a, k])\n"
    )
    namespace: dict = {"math": math, "np": np}  # numba has no math.cbrt; np.cbrt is libm's
    exec(src, namespace)  # a fixed template with a name from UNARY, not user input
    return njit(error_model="numpy", nogil=True)(namespace["loop"])


@njit(error_model="numpy", nogil=True)
def _pow_libm(W, d, a, b, n, reps):
    for _ in range(reps):
        for k in range(n):
            W[d, k] = W[a, k] ** W[b, k]


@njit(error_model="numpy", nogil=True)
def _ours1(row, W, d, a, n, reps):
    for _ in range(reps):
        row(W, d, a, n)


@njit(error_model="numpy", nogil=True)
def _ours2(row, W, d, a, b, n, reps):
    for _ in range(reps):
        row(W, d, a, b, n)


_SPEED_ARGS = {
    "exp": (-20.0, 20.0), "log": (1e-3, 1e3), "log10": (1e-3, 1e3), "sinh": (-5.0, 5.0),
    "cosh": (-5.0, 5.0), "tanh": (-5.0, 5.0), "asinh": (-50.0, 50.0), "acosh": (1.0, 50.0),
    "atanh": (-0.99, 0.99), "cbrt": (-1e3, 1e3),
}  # fmt: skip
_UFUNC = {
    "asinh": np.arcsinh, "acosh": np.arccosh, "atanh": np.arctanh, "pow": np.power,
}  # fmt: skip


def speed(name: str, seconds: float) -> tuple[float, float, float]:
    if name in CONST_POW:
        return speed_pow_vs(seconds, CONST_POW[name])
    rng = np.random.default_rng(5)
    W = np.zeros((4, ROWS))
    if name == "pow":
        W[0] = np.exp(rng.uniform(-3, 3, ROWS))
        W[1] = rng.uniform(-4, 4, ROWS)
        ours = lambda reps: _ours2(E.pow_row_vv, W, 2, 0, 1, ROWS, reps)  # noqa: E731
        libm = lambda reps: _pow_libm(W, 3, 0, 1, ROWS, reps)  # noqa: E731
        uf = lambda reps: [np.power(W[0], W[1], out=W[3]) for _ in range(reps)]  # noqa: E731
    else:
        W[0] = rng.uniform(*_SPEED_ARGS[name], ROWS)
        row = getattr(E, f"{name}_row")
        loop = _libm_loop(name)
        ufunc = _UFUNC.get(name, getattr(np, name, None))
        ours = lambda reps: _ours1(row, W, 2, 0, ROWS, reps)  # noqa: E731
        libm = lambda reps: loop(W, 3, 0, ROWS, reps)  # noqa: E731
        uf = lambda reps: [ufunc(W[0], out=W[3]) for _ in range(reps)]  # noqa: E731
    best = [0.0, 0.0, 0.0]
    for f in (ours, libm, uf):
        f(2)  # compile
    for _ in range(5):
        for i, f in enumerate((ours, libm, uf)):
            reps = max(1, int(seconds * 2e7 / ROWS / 5))
            t = time.thread_time()
            f(reps)
            best[i] = max(best[i], reps * ROWS / (time.thread_time() - t) / 1e6)
    return best[0], best[1], best[2]


@njit(error_model="numpy", nogil=True)
def _ours_vs(W, d, a, s, n, reps):
    for _ in range(reps):
        E.pow_row_vs(W, d, a, s, n)


@njit(error_model="numpy", nogil=True)
def _libm_vs(W, d, a, s, n, reps):
    for _ in range(reps):
        for k in range(n):
            W[d, k] = W[a, k] ** s


def speed_pow_vs(seconds: float, c: float = 2.5) -> tuple[float, float, float]:
    """pow with a constant exponent c, the common case in eq. (13) formulas."""
    W = np.zeros((4, ROWS))
    W[0] = np.random.default_rng(6).uniform(0.0, 10.0, ROWS)
    fs = (
        lambda reps: _ours_vs(W, 2, 0, c, ROWS, reps),
        lambda reps: _libm_vs(W, 3, 0, c, ROWS, reps),
        lambda reps: [np.power(W[0], c, out=W[3]) for _ in range(reps)],
    )
    best = [0.0, 0.0, 0.0]
    for f in fs:
        f(2)
    for _ in range(5):
        for i, f in enumerate(fs):
            reps = max(1, int(seconds * 2e7 / ROWS / 5))
            t = time.thread_time()
            f(reps)
            best[i] = max(best[i], reps * ROWS / (time.thread_time() - t) / 1e6)
    return best[0], best[1], best[2]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1_000_000, help="arguments per function")
    ap.add_argument("--quick", action="store_true", help="shorter speed runs")
    ap.add_argument("--only", nargs="*", default=None, help="a subset of the functions")
    args = ap.parse_args()
    np.seterr(all="ignore")  # the hard ranges overflow on purpose
    names = args.only or ["exp", "log", "pow", *CONST_POW, *UNARY[2:]]
    rng = np.random.default_rng(20261201)
    rows = []
    with multiprocessing.get_context("fork").Pool(2) as pool:
        for name in names:
            t = time.time()
            acc = accuracy(name, args.n, pool, rng)
            sp = speed(name, 0.05 if args.quick else 0.3)
            rows.append((name, acc, sp))
            print(
                f"# {name}: {acc['n']} args, row==array bits: {acc['same_bits']}, "
                f"{acc['checked']} recomputed with mpmath, stage-1 deviation "
                f"{acc['stage1_dev']:.4f} ulp, worst at {acc['worst']}, {time.time() - t:.0f} s"
                + (
                    ""
                    if acc["max_exact"] is None
                    else f"; max on the exact-product path {acc['max_exact']:.4f} ulp"
                ),
                flush=True,
            )
    if "pow" in names:
        vs = speed_pow_vs(0.05 if args.quick else 0.3)
        print(
            f"# pow with a scalar exponent (pow_row_vs, x^2.5: the general path): {vs[0]:.0f} M/s, "
            f"numba x**2.5 loop {vs[1]:.0f} M/s, np.power(x, 2.5) {vs[2]:.0f} M/s"
        )
    print()
    print(
        "| function | arguments | max ulp | share > 0.5 ulp | `NAME_row` (M/s) | `math.NAME` loop in numba (M/s) | numpy ufunc (M/s) |"
    )
    print("|---|---|---|---|---|---|---|")
    for name, acc, (ours, libm, uf) in rows:
        print(
            f"| {name} | {acc['n']:,} | {acc['max']:.3f} | {100 * acc['share']:.3f} % | "
            f"{ours:.0f} | {libm:.0f} | {uf:.0f} |"
        )


if __name__ == "__main__":
    main()
