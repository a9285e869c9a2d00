"""Derive the polynomial coefficients of ``generator/elementary/trig.py`` (mpmath Remez).

Each kernel approximates a smooth function ``g(z)`` of ``z = y*y`` on ``[0, zmax]`` by a
polynomial ``P(z)`` of degree ``deg`` minimising the largest *relative* error ``|P/g - 1|``
(linear Remez exchange on a dense grid, mpmath at 90 digits). The coefficients are then rounded
to doubles and the error of the rounded polynomial is measured again. Run::

    python -m tools.trig_coefficients            # prints the tables pasted into trig.py

and compare with the constants in ``trig.py`` (about 80 s; ``tests/generator/
test_elementary_trig.py`` checks the relative error of every kernel's polynomial against
mpmath on its range).
"""

from __future__ import annotations

import mpmath as mp

mp.mp.dps = 90


def _g_sin(z):  # (sin y - y) / y^3
    y = mp.sqrt(z)
    return (mp.sin(y) - y) / (y**3)


def _g_cos(z):  # (cos y - 1 + z/2) / z^2
    y = mp.sqrt(z)
    return (mp.cos(y) - 1 + z / 2) / (z**2)


def _g_tan(z):  # (tan y - y) / y^3
    y = mp.sqrt(z)
    return (mp.tan(y) - y) / (y**3)


def _g_asin(z):  # (asin x - x) / x^3
    x = mp.sqrt(z)
    return (mp.asin(x) - x) / (x**3)


def _g_atan(z):  # (atan t - t) / t^3
    t = mp.sqrt(z)
    return (mp.atan(t) - t) / (t**3)


# name: (function, zmax, degree)
KERNELS = {
    "SIN": (_g_sin, (mp.pi / 4) ** 2 * mp.mpf("1.0001"), 6),
    "COS": (_g_cos, (mp.pi / 4) ** 2 * mp.mpf("1.0001"), 6),
    "TAN": (_g_tan, (mp.pi / 8) ** 2 * mp.mpf("1.0001"), 10),
    "ASIN": (_g_asin, mp.mpf("0.25"), 13),
    "ATAN": (_g_atan, mp.mpf(7) ** 2 / 16**2, 11),
}

_ZMIN = mp.mpf("1e-24")  # g is analytic at 0; stay clear of 0/0 in the formulas above


def _horner(c, z):
    r = mp.mpf(0)
    for a in reversed(c):
        r = r * z + a
    return r


def remez(g, zmax, deg, iters=30, grid=4000):
    """Minimax relative-error polynomial of degree ``deg`` for ``g`` on ``[0, zmax]``."""
    n = deg + 2
    a, b = _ZMIN, zmax
    # Chebyshev extrema as the first reference.
    ref = [(a + b) / 2 - (b - a) / 2 * mp.cos(mp.pi * i / (n - 1)) for i in range(n)]
    pts = [a + (b - a) * (1 - mp.cos(mp.pi * i / grid)) / 2 for i in range(grid + 1)]
    gv = {p: g(p) for p in pts}
    c = None
    for _ in range(iters):
        rows, rhs = [], []
        for i, z in enumerate(ref):
            gz = g(z)
            rows.append([z**j for j in range(deg + 1)] + [(-1) ** i * gz])
            rhs.append(gz)
        sol = mp.lu_solve(mp.matrix(rows), mp.matrix(rhs))
        c = [sol[j] for j in range(deg + 1)]
        err = [(_horner(c, p) - gv[p]) / gv[p] for p in pts]
        # Local extrema of the error, alternating in sign, keeping the largest per run.
        ext = []
        for i, e in enumerate(err):
            left = err[i - 1] if i > 0 else None
            right = err[i + 1] if i < grid else None
            if (left is None or abs(e) >= abs(left)) and (right is None or abs(e) >= abs(right)):
                ext.append((pts[i], e))
        alt = []
        for p, e in ext:
            if alt and mp.sign(alt[-1][1]) == mp.sign(e):
                if abs(e) > abs(alt[-1][1]):
                    alt[-1] = (p, e)
            else:
                alt.append((p, e))
        while len(alt) > n:  # drop the smaller end
            if abs(alt[0][1]) < abs(alt[-1][1]):
                alt.pop(0)
            else:
                alt.pop()
        if len(alt) < n:
            break
        ref = [p for p, _ in alt]
    return c


def max_rel_error(g, zmax, coeffs, grid=4000):
    """Largest relative error of the polynomial with these (double) coefficients."""
    pts = [_ZMIN + (zmax - _ZMIN) * (1 - mp.cos(mp.pi * i / grid)) / 2 for i in range(grid + 1)]
    return max(abs((_horner([mp.mpf(c) for c in coeffs], p) - g(p)) / g(p)) for p in pts)


def fit_all() -> dict[str, list[float]]:
    """All kernels' coefficients, rounded to doubles."""
    return {
        name: [float(c) for c in remez(g, zmax, deg)] for name, (g, zmax, deg) in KERNELS.items()
    }


def main() -> None:
    for name, coeffs in fit_all().items():
        g, zmax, deg = KERNELS[name]
        err = max_rel_error(g, zmax, coeffs)
        print(
            f"# {name}: degree {deg} in z on [0, {mp.nstr(zmax, 6)}], "
            f"max relative error {mp.nstr(err, 3)} (2^{mp.nstr(mp.log(err, 2), 4)})"
        )
        print(f"_{name} = (")
        for c in coeffs:
            print(f"    {c!r},")
        print(")")


if __name__ == "__main__":
    main()
