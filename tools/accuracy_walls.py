"""Accuracy of the walls' classification (issue 11): each suspect crossing's kind against the
edge itself, looked at closely.

For every suspect crossing (the crossings the samples alone do not settle, ``walls._crossings``)
of the shapes of ``benchmarks/walls_cost.py`` (the named ones and the first ``--n`` screened
draws of ``--seed``, at ``--grid``³), the *truth*: F sampled at ``--fine`` points along the edge (the
plain points evaluator, nothing shared); where F changes side exactly once, that change is
bisected ``--bisect`` more times (to about 2^-44 of the edge), and the kind read from |F| at the
two ends of the last bracket, against the samples' scale ``S = |fa| + |fb|``:

- root: both ends within ``1e-6 S`` (F goes to 0);
- pole: F infinite at an end, or both ends beyond ``1e4 S`` (F goes to infinity);
- jump: both ends between ``1e-3 S`` and ``1e3 S``, or F NaN at an end (the edge of a domain);
- *ambiguous*, left out: several side changes on the edge (F oscillates faster than the fine
  sampling resolves, or more than one crossing in one edge) or ends in neither band.

Prints per shape and in all: the suspects, the unambiguous ones, how many the classification now
gets wrong and main's before the second cost work (``tests/support/walls_main.py``) in the
same run, the points each evaluated, and the confusions (truth -> got).

    python -m tools.accuracy_walls [--n 24] [--seed 7] [--grid 64] [--no-named]
"""

from __future__ import annotations

import argparse
from collections import Counter

import numpy as np

import surfgen.generator.mesh.mesh as mesh_module
import surfgen.generator.mesh.walls as walls_module
from benchmarks.workloads import NAMED, sampled_shapes
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.tape import points_evaluator
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.mesh import JUMP, POLE, ROOT
from tests.support.walls_main import main_classify

AMBIGUOUS = 255
NAMES = {ROOT: "root", POLE: "pole", JUMP: "jump"}


def truth(tree, field, edges, fine: int, bisections: int):
    """Rows of the suspects in ``edges`` and their kinds by the close look (module docstring)."""
    values = np.ascontiguousarray(field.values, dtype=np.float64).reshape(-1)
    shape = np.asarray(field.values.shape, dtype=np.int64)
    _, idx, fa, fb, _ = walls_module._crossings(
        values, shape, edges, 0.0, walls_module.SMOOTH_RATIO
    )
    plain = points_evaluator(tree).plain
    axes = field.grid.axes()
    axis = edges[idx, 0]
    start = np.stack([axes[k][edges[idx, 1 + k]] for k in range(3)], axis=1)
    h = np.asarray(field.grid.spacing)[axis]
    t = np.linspace(0.0, 1.0, fine)
    kinds = np.full(idx.size, AMBIGUOUS, dtype=np.uint8)
    for c0 in range(0, idx.size, 2048):
        rows = np.arange(c0, min(c0 + 2048, idx.size))
        m = rows.size
        r = np.arange(m)

        def f_at(s, rows=rows, r=r):  # F - level at s (m,) along each edge
            p = start[rows].copy()
            p[r, axis[rows]] += s * h[rows]
            return plain(p[:, 0], p[:, 1], p[:, 2])

        p = np.repeat(start[rows], fine, axis=0)  # fine points along each edge, edge by edge
        p[np.arange(m * fine), np.repeat(axis[rows], fine)] += np.tile(t, m) * np.repeat(
            h[rows], fine
        )
        with np.errstate(all="ignore"):
            f = plain(p[:, 0], p[:, 1], p[:, 2]).reshape(m, fine)
        f[:, 0], f[:, -1] = fa[rows], fb[rows]
        inside = np.isfinite(f) & (f < 0.0)
        change = inside[:, 1:] != inside[:, :-1]
        k = change.argmax(axis=1)
        lo, hi, f_lo, f_hi = t[k], t[k + 1], f[r, k], f[r, k + 1]
        lo_inside = inside[r, k]
        for _ in range(bisections):
            mid = 0.5 * (lo + hi)
            with np.errstate(all="ignore"):
                f_mid = f_at(mid)
            same = (np.isfinite(f_mid) & (f_mid < 0.0)) == lo_inside
            lo, f_lo = np.where(same, mid, lo), np.where(same, f_mid, f_lo)
            hi, f_hi = np.where(same, hi, mid), np.where(same, f_hi, f_mid)
        scale = np.nan_to_num(np.abs(fa[rows]), posinf=0.0) + np.nan_to_num(
            np.abs(fb[rows]), posinf=0.0
        )
        with np.errstate(invalid="ignore"):
            big, small = np.fmax(np.abs(f_lo), np.abs(f_hi)), np.fmin(np.abs(f_lo), np.abs(f_hi))
            root = big <= 1e-6 * scale
            pole = np.isinf(f_lo) | np.isinf(f_hi) | (small >= 1e4 * scale)
            nan = np.isnan(f_lo) | np.isnan(f_hi)
            jump = nan | ((small >= 1e-3 * scale) & (big <= 1e3 * scale))
        got = np.full(m, AMBIGUOUS, dtype=np.uint8)
        got[jump & ~root & ~pole] = JUMP
        got[pole & ~nan] = POLE
        got[root] = ROOT
        got[change.sum(axis=1) != 1] = AMBIGUOUS
        kinds[rows] = got
    return idx, kinds


def shapes(args):
    if not args.no_named:
        for name, formula, half in NAMED:
            tree = parse(formula)
            yield name, tree, evaluate(tree, Grid(Box.cube(half), (args.grid,) * 3), threads=1)
    yield from sampled_shapes(args.n, args.seed, args.grid)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=24)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--grid", type=int, default=64)
    parser.add_argument("--fine", type=int, default=257)
    parser.add_argument("--bisect", type=int, default=36)
    parser.add_argument("--no-named", action="store_true")
    args = parser.parse_args()
    classifiers = {
        "now": lambda f, t, e: walls_module._classify(f, t, {}, 0.0, e),
        "main": lambda f, t, e: main_classify(f, t, {}, 0.0, e),
    }
    totals = {k: Counter() for k in classifiers}
    confusion = {k: Counter() for k in classifiers}
    print(f"{'shape':>10} {'suspect':>8} {'clear':>7} {'wrong':>6} {'main':>6} {'points':>7} "
          f"{'p.main':>7}")  # fmt: skip
    for name, tree, field in shapes(args):
        _, edges = mesh_module.extract_with_edges(field, 0.0, True)
        edges = np.ascontiguousarray(edges, dtype=np.int64)
        idx, kinds = truth(tree, field, edges, args.fine, args.bisect)
        clear = kinds != AMBIGUOUS
        row = {}
        for label, classify in classifiers.items():
            got, _, points = classify(field, tree, edges)
            got = got[idx]
            wrong = clear & (got != kinds)
            row[label] = (int(wrong.sum()), points)
            totals[label].update(wrong=int(wrong.sum()), points=points)
            confusion[label].update(zip(kinds[wrong].tolist(), got[wrong].tolist(), strict=True))
        totals["now"].update(suspects=idx.size, clear=int(clear.sum()))
        print(f"{name:>10} {idx.size:>8} {int(clear.sum()):>7} {row['now'][0]:>6} "
              f"{row['main'][0]:>6} {row['now'][1]:>7} {row['main'][1]:>7}", flush=True)  # fmt: skip
    suspects, clear = totals["now"]["suspects"], totals["now"]["clear"]
    print(f"\nat {args.grid}^3: {suspects} suspect crossings, {clear} unambiguous "
          f"({suspects - clear} ambiguous: several side changes on the edge)")  # fmt: skip
    for label in classifiers:
        wrong, points = totals[label]["wrong"], totals[label]["points"]
        pairs = ", ".join(
            f"{NAMES[a]}->{NAMES[b]} {n}" for (a, b), n in sorted(confusion[label].items())
        )
        print(f"{label:>5}: wrong on {wrong} of {clear} ({wrong / max(clear, 1):.2%}), "
              f"{points} points ({points / max(suspects, 1):.2f} a suspect); {pairs}")  # fmt: skip


if __name__ == "__main__":
    main()
