"""The Taylor forms of :mod:`~surfgen.generator.eval.interval_poly`'s polynomials over boxes:
the Taylor shift's pairs of a polynomial (:func:`taylor_pairs`) and the compiled kernel that
bounds ``Σ_β d_β t^β`` over many boxes at once, with the rounding of its coefficients, of the
reach ``h^β``, of the sums and the evaluator's own (:func:`taylor_bounds`; the intervals
reference's section "Expanded polynomials: Taylor forms" gives the argument). The pairs may
come in two groups whose terms each box multiplies by a factor of its own: a quotient's centred
numerator ``P - r D`` is P's pairs and D's, times 1 and ``-r``.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit

from surfgen.generator.eval.tape import run_at_once
from surfgen.generator.jit.options import KERNEL

#: The largest power of one variable in a polynomial.
MAX_DEGREE = 16
#: The most pairs of a polynomial's Taylor shift (monomial α, β <= α): its cost a box.
MAX_PAIRS = 1024
#: Boxes a thread bounds at least (fewer: one run).
THREAD_BOXES = 4096
#: Boxes a Taylor kernel's inner loops run over at once (the compiler vectorises them).
CHUNK = 32


def taylor_pairs(exps: np.ndarray, coefs: np.ndarray, tags=None) -> tuple[np.ndarray, ...] | None:
    """The Taylor shift's pairs: for each monomial α and β <= α, the coefficient
    ``c_α · Π binom(α_i, β_i)`` (P,), the power ``α - β`` of the centre (P, 3), the group of
    its monomial (``tags``, 0 for all where None: :func:`_taylor_kernel`'s ``which``), where
    each β's pairs start (B,) and the β's (B, 3); None beyond :data:`MAX_PAIRS`."""
    if int(np.prod(exps + 1, axis=1).sum()) > MAX_PAIRS:
        return None
    tags = [0] * len(exps) if tags is None else list(tags)
    coef, expo, which, into, betas = [], [], [], [], {}
    for e, c, g in zip(exps.tolist(), coefs.tolist(), tags, strict=True):
        for b0 in range(e[0] + 1):
            for b1 in range(e[1] + 1):
                for b2 in range(e[2] + 1):
                    k = math.comb(e[0], b0) * math.comb(e[1], b1) * math.comb(e[2], b2)
                    coef.append(c * k)
                    expo.append((e[0] - b0, e[1] - b1, e[2] - b2))
                    which.append(g)
                    into.append(betas.setdefault((b0, b1, b2), len(betas)))
    order = np.argsort(np.array(into), kind="stable")  # each β's pairs together
    into_arr = np.array(into, dtype=np.int64)[order]
    starts = np.flatnonzero(np.r_[True, into_arr[1:] != into_arr[:-1]])
    return (np.array(coef)[order], np.array(expo, dtype=np.int64).reshape(-1, 3)[order],
            np.array(which, dtype=np.int64)[order], starts,
            np.array(list(betas), dtype=np.int64).reshape(-1, 3))  # fmt: skip


def taylor_bounds(taylor, absolute, ops: int, u: float, lo, hi, threads: int, w=None):
    """:func:`_taylor_kernel` over the boxes in ``threads`` runs at once; ``w`` (2, boxes):
    each box's factors of the pairs of either group (``taylor``'s ``which``), None for a
    polynomial's own (its terms not multiplied: 5-6 % of its time, measured); ``u`` the unit
    roundoff (the caller's: its margin test zeroes it)."""
    coef, expo, which, starts, betas = taylor
    abs_exps, abs_coefs, abs_which = absolute
    out_lo, out_hi = np.empty(len(lo)), np.empty(len(lo))
    runs = max(1, min(int(threads), len(lo) // THREAD_BOXES))
    cuts = [len(lo) * r // runs for r in range(runs + 1)]
    unweighted = np.ones((2, 1))

    def run(r: int) -> None:
        v = slice(cuts[r], cuts[r + 1])
        wv = unweighted if w is None else np.ascontiguousarray(w[:, v])
        _taylor_kernel(coef, expo, which, starts, betas, abs_exps, abs_coefs, abs_which,
                       float(ops), u, lo[v], hi[v], wv, w is not None, out_lo[v],
                       out_hi[v])  # fmt: skip

    run_at_once([functools.partial(run, r) for r in range(runs)])
    return out_lo, out_hi


@njit(**KERNEL)
def _powers_of(lo, hi, k0, m, cp, hp, tp):
    """Boxes ``k0:k0+m``'s powers ``j < MAX_DEGREE + 1`` (by repeated products: j roundings
    each) of their centre ``c`` (``cp[a, j, k]``), half-width ``h`` (rounded up: ``hp``) and
    largest ``|x|`` (``tp``), per axis a."""
    for a in range(3):
        for k in range(m):
            c = (lo[k0 + k, a] + hi[k0 + k, a]) / 2
            h = max(
                np.nextafter(hi[k0 + k, a] - c, np.inf), np.nextafter(c - lo[k0 + k, a], np.inf)
            )
            t = max(abs(lo[k0 + k, a]), abs(hi[k0 + k, a]))
            cp[a, 0, k] = hp[a, 0, k] = tp[a, 0, k] = 1.0
            for j in range(1, MAX_DEGREE + 1):
                cp[a, j, k] = cp[a, j - 1, k] * c
                hp[a, j, k] = hp[a, j - 1, k] * h
                tp[a, j, k] = tp[a, j - 1, k] * t


@njit(**KERNEL)
def _taylor_kernel(coef, expo, which, starts, betas, abs_exps, abs_coefs, abs_which, ops, u, lo,
                   hi, w, weighted, out_lo, out_hi):  # fmt: skip
    """Per box: ``Σ_β d_β t^β`` over ``|t| <= h`` around ``c``, plus the roundings of the
    ``d_β`` (``4 (P + 57) u`` of their terms' magnitudes: each term ``3 MAX_DEGREE + 4``
    roundings at most, each sum P), of the reach ``h^β`` and of the sums (``slack``), and the
    evaluator's rounding of P (``2 (ops + 2) u P~(|x|)``). Each pair's term (and ``P~``'s) is
    multiplied by its box's factor of its group where ``weighted`` (``w[which[q], k]``: 1 and
    ``-r`` for a quotient's centred numerator ``P - r D``; a polynomial's own are not). The
    boxes are taken :data:`CHUNK` at a time, each pair's term computed for all of them in one
    loop (the same operations, in the same order, for each box: twist-0's 636 pairs 5 -> 0.8
    microseconds a box)."""
    n_pairs, n_betas = coef.shape[0], betas.shape[0]
    cp = np.empty((3, MAX_DEGREE + 1, CHUNK))
    hp = np.empty((3, MAX_DEGREE + 1, CHUNK))
    tp = np.empty((3, MAX_DEGREE + 1, CHUNK))
    sums = np.empty((6, CHUNK))  # the sums' low and high ends, magnitude, d, size, P~
    sum_lo, sum_hi, mag, d, size, p_abs = sums[0], sums[1], sums[2], sums[3], sums[4], sums[5]
    rel = 4.0 * (n_pairs + 3 * MAX_DEGREE + 9) * u
    for k0 in range(0, lo.shape[0], CHUNK):
        m = min(CHUNK, lo.shape[0] - k0)
        _powers_of(lo, hi, k0, m, cp, hp, tp)
        sums[:3] = 0.0
        for b in range(n_betas):
            d[:] = 0.0
            size[:] = 0.0
            for q in range(starts[b], starts[b + 1] if b + 1 < n_betas else n_pairs):
                cq, c0, c1, c2 = coef[q], cp[0, expo[q, 0]], cp[1, expo[q, 1]], cp[2, expo[q, 2]]
                if weighted:
                    wq = w[which[q], k0:]
                    for k in range(m):
                        t = cq * c0[k] * c1[k] * c2[k] * wq[k]
                        d[k] += t
                        size[k] += abs(t)
                else:
                    for k in range(m):
                        t = cq * c0[k] * c1[k] * c2[k]
                        d[k] += t
                        size[k] += abs(t)
            b0, b1, b2 = betas[b, 0], betas[b, 1], betas[b, 2]
            centre = b0 == 0 and b1 == 0 and b2 == 0
            even = b0 % 2 == 0 and b1 % 2 == 0 and b2 % 2 == 0
            h0, h1, h2 = hp[0, b0], hp[1, b1], hp[2, b2]
            for k in range(m):
                err = rel * size[k]
                if centre:
                    tlo, thi = d[k] - err, d[k] + err
                else:
                    reach = h0[k] * h1[k] * h2[k] * (1.0 + 64.0 * u)
                    low = 0.0 if even else -reach
                    if d[k] >= 0:
                        tlo, thi = d[k] * low - err * reach, d[k] * reach + err * reach
                    else:
                        tlo, thi = d[k] * reach - err * reach, d[k] * low + err * reach
                sum_lo[k] += tlo
                sum_hi[k] += thi
                mag[k] += abs(tlo) + abs(thi)
        p_abs[:] = 0.0
        for q in range(abs_exps.shape[0]):
            ac = abs_coefs[q]
            t0, t1, t2 = tp[0, abs_exps[q, 0]], tp[1, abs_exps[q, 1]], tp[2, abs_exps[q, 2]]
            if weighted:
                wq = w[abs_which[q], k0:]
                for k in range(m):
                    p_abs[k] += ac * t0[k] * t1[k] * t2[k] * abs(wq[k])
            else:
                for k in range(m):
                    p_abs[k] += ac * t0[k] * t1[k] * t2[k]
        for k in range(m):
            slack = 4.0 * (n_betas + 4) * u * mag[k]
            err_p = 2.0 * (ops + 2.0) * u * p_abs[k] * (1.0 + 4.0 * (abs_exps.shape[0] + 57) * u)
            out_lo[k0 + k] = np.nextafter(sum_lo[k] - slack - err_p, -np.inf)
            out_hi[k0 + k] = np.nextafter(sum_hi[k] + slack + err_p, np.inf)


@njit(**KERNEL)
def centre_values(exps, coefs, lo, hi):
    """The polynomial ``Σ coefs[m] x^exps[m]`` at each box's centre, in floats (a quotient's
    centre value ``r``: any number keeps the centred form exact, so no bound on its rounding),
    from the centre's powers :func:`_powers_of` makes, :data:`CHUNK` boxes at a time."""
    out = np.zeros(lo.shape[0])
    cp = np.empty((3, MAX_DEGREE + 1, CHUNK))
    hp = np.empty((3, MAX_DEGREE + 1, CHUNK))
    tp = np.empty((3, MAX_DEGREE + 1, CHUNK))
    for k0 in range(0, lo.shape[0], CHUNK):
        m = min(CHUNK, lo.shape[0] - k0)
        _powers_of(lo, hi, k0, m, cp, hp, tp)
        for q in range(exps.shape[0]):
            cq, c0, c1, c2 = coefs[q], cp[0, exps[q, 0]], cp[1, exps[q, 1]], cp[2, exps[q, 2]]
            for k in range(m):
                out[k0 + k] += cq * c0[k] * c1[k] * c2[k]
    return out
