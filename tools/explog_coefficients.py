"""Derive the polynomial coefficients of ``generator/elementary/explog.py`` (reproducible).

Each kernel polynomial is a Chebyshev interpolant (near-minimax) computed by mpmath at 60
digits, then rounded to float64; the script prints the coefficients as Python literals and the
maximum error of the *rounded* polynomial measured on a dense grid, so a change of interval or
degree can be checked before pasting the numbers into the module.

    .venv/bin/python -m tools.explog_coefficients

Kernels (w = r^2 where the function is even):
- ``EXP_Q``:   Q(r) = (e^r - 1 - r - r^2/2) / r^3           on |r| <= ln2/2 (+ margin)
- ``LOG_H``:   H(q) = (G(q) - 3 - q) / q^2, G(q) = 3 atanh(sqrt q)/sqrt q,  q = s^2 <= 0.04^2
- ``SINH_S``:  S(w) = (sinh(sqrt w) - sqrt w) / w^1.5       on w <= 0.5^2
- ``TANH_T``:  T(w) = (tanh(sqrt w) - sqrt w) / w^1.5       on w <= 0.125^2
"""

from __future__ import annotations

import mpmath as mp

mp.mp.dps = 60


def _q_exp(r):
    if r == 0:
        return mp.mpf(1) / 6
    return (mp.exp(r) - 1 - r - r * r / 2) / r**3


def _h_log(q):
    if q == 0:
        return mp.mpf(3) / 5
    s = mp.sqrt(q)
    return (3 * mp.atanh(s) / s - 3 - q) / (q * q)


def _s_sinh(w):
    if w == 0:
        return mp.mpf(1) / 6
    x = mp.sqrt(w)
    return (mp.sinh(x) - x) / (w * x)


def _t_tanh(w):
    if w == 0:
        return -mp.mpf(1) / 3
    x = mp.sqrt(w)
    return (mp.tanh(x) - x) / (w * x)


KERNELS = {
    # name: (function, interval, number of coefficients, weight(t) of the error as used)
    "EXP_Q": (_q_exp, (-0.3467, 0.3467), 10, lambda t: abs(t) ** 3),
    "LOG_H": (_h_log, (0.0, 0.04**2), 5, lambda t: t * t),
    "SINH_S": (_s_sinh, (0.0, 0.5**2), 7, lambda t: t**1.5),
    "TANH_T": (_t_tanh, (0.0, 0.125**2), 7, lambda t: t**1.5),
}


def fit(name: str) -> tuple[list[float], float]:
    """Coefficients (lowest degree first, float64) and the max weighted error after rounding."""
    f, (a, b), n, weight = KERNELS[name]
    poly, _ = mp.chebyfit(f, [a, b], n, error=True)
    coeffs = [float(c) for c in reversed(poly)]  # mpmath gives the highest degree first
    worst = mp.mpf(0)
    for i in range(2001):
        t = mp.mpf(a) + (mp.mpf(b) - a) * i / 2000
        p = mp.mpf(0)
        for c in reversed(coeffs):
            p = p * t + mp.mpf(c)
        worst = max(worst, abs(p - f(t)) * weight(t))
    return coeffs, float(worst)


def main() -> None:
    for name in KERNELS:
        coeffs, err = fit(name)
        print(
            f"# {name}: degree {len(coeffs) - 1}, max weighted error {err:.3g} ({mp.log(err, 2) if err else -999:.1f} bits)"
        )
        print(f"{name} = (")
        for c in coeffs:
            print(f"    {c!r},")
        print(")")


if __name__ == "__main__":
    main()
