"""Accuracy and speed of the closed-form round trips (``generator/elementary/roundtrip.py``).

    nice -n 10 .venv/bin/python -m tools.accuracy_roundtrip             # 10^6 arguments
    .venv/bin/python -m tools.accuracy_roundtrip --n 20000              # a smoke run

Arguments: a quarter uniform in [-20, 20], a quarter log-uniform in magnitude up to 2^24 (the
vectorised reduction's range), an eighth in (2^24, 2^50] (the per-lane Dekker reduction), and
the hard cases: the doubles nearest to k*pi/2 and their neighbours for |k| up to 2^24 (the jumps
and kinks, and arguments whose remainder cancels to a few ulp of u), tiny and subnormal u.
Each argument's exact remainder ``u - k*pi`` is computed once with mpmath at 50 digits (k = u/pi
rounded), and the four closed forms' exact values follow from it; errors in ulps of the exact
value. Every argument is also checked bit for bit: numba row == numpy twin.

Speed: M evaluations per second of each row on 1024 arguments in [-20, 20], interleaved with the
direct two-call forms (surfgen's own rows, e.g. tan_row then atan_row) in one run, best of 60
short timings (wall clock: expect +-20 % on a shared machine).
"""

from __future__ import annotations

import argparse
import multiprocessing
import time

import mpmath as mp
import numpy as np
from numba import njit

from surfgen.generator import elementary as E
from surfgen.generator.elementary import roundtrip as R


def arguments(n: int, rng: np.random.Generator) -> np.ndarray:
    q = n // 4
    e = n // 8
    k = rng.integers(-(2**24), 2**24, e).astype(float)
    near = k * (np.pi / 2)
    hard = np.concatenate(
        [
            near,
            np.nextafter(near, np.inf),
            np.nextafter(near, -np.inf),
            rng.uniform(-1e-300, 1e-300, 64),
        ]
    )
    u = np.concatenate(
        [
            rng.uniform(-20.0, 20.0, q),
            rng.choice([-1.0, 1.0], q) * 2.0 ** rng.uniform(-30, 24, q),
            rng.choice([-1.0, 1.0], e) * 2.0 ** rng.uniform(24, 50, e),
            hard,
        ]
    )
    return np.concatenate([u, rng.uniform(-20.0, 20.0, max(0, n - u.size))])[:n]


def _exact(job: tuple[list[float], dict[str, list[float]]]) -> dict[str, list[float]]:
    """Errors in ulps of the exact values (run in a worker)."""
    us, got = job
    mp.mp.dps = 50
    out: dict[str, list[float]] = {name: [] for name in got}
    for i, u in enumerate(us):
        x = mp.mpf(u)
        k = mp.floor(x / mp.pi + mp.mpf(0.5))
        r = x - k * mp.pi
        odd = int(k) % 2 == 1
        exact = {
            "atantan": r,
            "asinsin": -r if odd else r,
            "acoscos": mp.pi - abs(r) if odd else abs(r),
            "acotcot": r if r >= 0 else mp.pi + r,
        }
        for name in got:
            t = exact[name]
            # an ulp of the exact value's binade (mp.frexp: t = m 2^e, 1/2 <= |m| < 1)
            ulp = mp.ldexp(1, max(int(mp.frexp(t)[1]) - 1, -1022) - 52) if t else 2.0**-1074
            out[name].append(float(abs(mp.mpf(got[name][i]) - t) / ulp))
    return out


def accuracy(n: int, pool, rng: np.random.Generator) -> dict[str, dict]:
    u = arguments(n, rng)
    got, same = {}, {}
    for name in R.ROUND_TRIPS:
        twin = E.round_trip(name, u)
        W = np.vstack([u, np.zeros_like(u)])
        R.ROWS[name](W, 1, 0, u.size)
        got[name] = twin
        same[name] = bool(np.array_equal(W[1].view(np.int64), twin.view(np.int64)))
    chunks = np.array_split(np.arange(u.size), 64)
    jobs = [(u[c].tolist(), {name: got[name][c].tolist() for name in got}) for c in chunks]
    errs: dict[str, list[float]] = {name: [] for name in got}
    for part in pool.imap(_exact, jobs):
        for name in got:
            errs[name].extend(part[name])
    out = {}
    fast = np.abs(u) <= R.FAST
    for name in got:
        err = np.array(errs[name])
        out[name] = {
            "n": u.size,
            "max": float(err.max()),
            "max_fast": float(err[fast].max()),
            "max_mid": float(err[~fast].max()) if (~fast).any() else float("nan"),
            "share": float(np.mean(err > 0.5)),
            "same_bits": same[name],
            "worst": float(u[int(np.argmax(err))]),
        }
    return out


@njit(error_model="numpy", nogil=True)
def _loop(row, W, n, reps):
    for _ in range(reps):
        row(W, 1, 0, n)


_sin, _cos, _tan = (E.REGISTRY[f].row for f in ("sin", "cos", "tan"))
_asin, _acos, _atan = (E.REGISTRY[f].row for f in ("asin", "acos", "atan"))


@njit(error_model="numpy", nogil=True)
def _direct(name, W, n, reps):
    """The direct two-call form with surfgen's own rows (the rewrite's alternative)."""
    for _ in range(reps):
        if name == 0:
            _tan(W, 2, 0, n)
            _atan(W, 1, 2, n)
        elif name == 1:
            _sin(W, 2, 0, n)
            _asin(W, 1, 2, n)
        elif name == 2:
            _cos(W, 2, 0, n)
            _acos(W, 1, 2, n)
        else:
            _tan(W, 2, 0, n)
            for k in range(n):
                W[2, k] = 1.0 / W[2, k]
            _atan(W, 1, 2, n)
            for k in range(n):
                W[1, k] = 1.5707963267948966 - W[1, k]


def speed(points: int = 1024, rounds: int = 60) -> dict[str, tuple[float, float]]:
    rng = np.random.default_rng(5)
    W = np.zeros((3, points))
    W[0] = rng.uniform(-20.0, 20.0, points)
    rates = {}
    for i, name in enumerate(R.ROUND_TRIPS):
        row = R.ROWS[name]
        _loop(row, W, points, 2)
        _direct(i, W, points, 2)
        best = [0.0, 0.0]
        for _ in range(rounds):
            t = time.perf_counter()
            _loop(row, W, points, 20)
            best[0] = max(best[0], 20 * points / (time.perf_counter() - t) / 1e6)
            t = time.perf_counter()
            _direct(i, W, points, 20)
            best[1] = max(best[1], 20 * points / (time.perf_counter() - t) / 1e6)
        rates[name] = (best[0], best[1])
    return rates


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1_000_000, help="arguments")
    ap.add_argument("--workers", type=int, default=1, help="mpmath processes")
    args = ap.parse_args()
    rng = np.random.default_rng(20261202)
    t = time.time()
    with multiprocessing.get_context("fork").Pool(args.workers) as pool:
        acc = accuracy(args.n, pool, rng)
    print(f"# {args.n} arguments, {time.time() - t:.0f} s; mpmath at 50 digits for every argument")
    sp = speed()
    print(
        "\n| round trip | arguments | max ulp | max ulp, |u| <= 2^24 | max ulp, 2^24 < |u| <= 2^50"
        " | share > 0.5 ulp | row == twin | row (M/s) | direct form, surfgen's rows (M/s) |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name, a in acc.items():
        print(
            f"| {name} | {a['n']:,} | {a['max']:.3f} | {a['max_fast']:.3f} | {a['max_mid']:.3f} |"
            f" {100 * a['share']:.3f} % | {a['same_bits']} | {sp[name][0]:.0f} | {sp[name][1]:.0f} |"
        )


if __name__ == "__main__":
    main()
