"""The workloads the benchmarks share: eq. (13) formulas drawn at random, by the sampler, or
the 50 stored for the field-hash test (``tests/support/data/eq13_formulas.jsonl``); the shapes
with and without walls of ``walls_cost`` and ``tools/accuracy_walls.py``."""

from __future__ import annotations

import json
from collections.abc import Iterator

import numpy as np

from benchmarks.harness import ROOT
from surfgen.filters.verdict import screen_field
from surfgen.generator.errors import EmptySurface
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Field, Grid
from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.formula.expr import Expr
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.mesh import extract_mesh
from surfgen.generator.model import equation13 as eq
from surfgen.generator.model.sampler import SamplerConfig, choose_d, draw_equation
from surfgen.pipelines.run.config import load_config


def random_eq13(rng: np.random.Generator) -> Expr:
    """An eq. (13) formula drawn the way the sampler draws them (1-2 sums of 1-2 factors, power
    functions of 1-3 terms, real exponents on absolute values, trigonometric and constituent
    H and G, absolute values on elements)."""

    def power() -> eq.PowerFunction:
        absolute = bool(rng.random() < 0.6)
        terms = []
        for _ in range(rng.integers(1, 4)):
            exps = []
            for _ in range(3):
                if rng.random() < 0.35:
                    exps.append(0.0)
                elif absolute and rng.random() < 0.5:
                    exps.append(float(rng.choice([0.31, 0.5, 1.3, 1.38, 2.7, 3.3])))
                else:
                    exps.append(float(rng.integers(1, 5)))
            a = float(np.round(rng.uniform(0.2, 3.0), 2) * rng.choice([1, 1, -1]))
            terms.append(eq.PowerTerm(a, *exps))
        return eq.PowerFunction(tuple(terms), absolute)

    def transform(names) -> eq.Transform:
        if rng.random() < 0.2:
            name = str(rng.choice(list(eq.CONSTITUENT_TRANSFORMS)))
            params = {"r": 0.5 + rng.random(), "p": float(rng.integers(1, 6)), "h": 1.5}
            params["t"] = 0.3 if name != "rect3" else 0.5
            return eq.Transform(name, tuple(params[k] for k in eq.CONSTITUENT_TRANSFORMS[name]))
        return eq.Transform(str(rng.choice(names)))

    def exponent() -> float:
        return float(rng.choice([1, 1, 1, 2, 3, -1, 0.5, 1.5]))

    products = []
    for _ in range(rng.integers(1, 3)):
        factors = []
        for _ in range(rng.integers(1, 3)):
            powers = tuple(
                power() if rng.random() < 0.85 else eq.PowerFunction.constant() for _ in range(8)
            )
            factors.append(
                eq.Factor(
                    powers=powers,
                    lambdas=tuple(exponent() for _ in range(8)),
                    mus=tuple(exponent() for _ in range(4)),
                    h=transform(eq.DIRECT_TRIG),
                    g=transform(eq.INVERSE_TRIG),
                    absolute=tuple(bool(rng.random() < 0.4) for _ in range(6)),
                )
            )
        products.append(tuple(factors))
    return eq.Equation13(tuple(products), float(np.round(rng.uniform(-1, 1), 2))).to_tree()


def kept_eq13(rng: np.random.Generator, tries: int = 100) -> Expr:
    """A random eq. (13) formula (own generator) whose 16^3 field changes sign."""
    coarse = Grid(Box.cube(2.0), (16, 16, 16))
    for _ in range(tries):
        tree = random_eq13(rng)
        v = evaluate_reference(tree, coarse).values
        if (v < 0).any() and (v > 0).any():
            return tree
    return tree


STORED = ROOT / "tests" / "support" / "data" / "eq13_formulas.jsonl"


def stored_eq13(count: int) -> list[tuple[Expr, Box]]:
    """The 50 eq. (13) formulas stored for the field-hash test (drawn once by the sampler,
    seed 7): the same formulas whatever the sampler becomes."""
    with open(STORED) as f:
        rows = [json.loads(line) for line in f][:count]
    return [(parse(r["formula"]), Box(tuple(r["lo"]), tuple(r["hi"]))) for r in rows]


def sampled_eq13(seed: int, count: int) -> list[tuple[Expr, Box]]:
    """The first ``count`` formulas of the project's sampler (default config) that get a d,
    with their boxes."""
    cfg = SamplerConfig()
    out, index = [], 0
    while len(out) < count:
        draw = draw_equation(seed, index, cfg)
        index += 1
        d = choose_d(draw, cfg, evaluator="reference")
        if d is not None:
            out.append((draw.equation.with_d(d).to_tree(), draw.box))
    return out


# ----------------------------------------------------------------------- shapes with walls

NAMED = [
    # (name, formula, half side of the box); walls first
    ("tan", "tan(x)+0.3*y", 3.0),
    ("tan*tan", "tan(x)*tan(y)-z", 3.0),
    ("1/x", "1/x+y+z", 2.0),
    ("atan(tan)", "atan(tan(2*x))+0.5-0.3*y*z", 3.0),
    ("stair1", "stair1(x,0.5,1,4)+stair1(y,0.5,1,4)-z", 2.0),
    ("stair2", "stair2(x*y,0.7,1)-z", 2.0),
    ("saw1", "saw1(x+y,0.6,4)-0.3*z^2", 2.0),
    ("sphere", "x^2+y^2+z^2-1", 1.3),
    ("torus", "(sqrt(x^2+y^2)-1)^2+z^2-0.16", 1.5),
    ("gyroid", "sin(3*x)*cos(3*y)+sin(3*y)*cos(3*z)+sin(3*z)*cos(3*x)", 2.0),
]


def sampled_shapes(n: int, seed: int, grid: int) -> Iterator[tuple[str, Expr, Field]]:
    """The first ``n`` draws of ``seed`` whose coarse field passes the sampler's screen and
    whose ``grid``³ field has a surface: ``(name, tree, field)``, named ``#index``."""
    config = load_config()
    found = index = 0
    while found < n and index < 50 * n:
        draw = draw_equation(seed, index, config.sampler)
        index += 1
        d = choose_d(draw, config.sampler, threads=1)
        if d is None:
            continue
        tree = draw.equation.with_d(d).to_tree()
        coarse = evaluate(tree, Grid(draw.box, (config.filters.coarse_grid,) * 3), threads=1)
        if not screen_field(coarse.values, 0.0, config.filters, coarse=True).accepted:
            continue
        field = evaluate(tree, Grid(draw.box, (grid,) * 3), threads=1)
        try:
            extract_mesh(field, 0.0, cap=True)
        except EmptySurface:
            continue
        found += 1
        yield f"#{index - 1}", tree, field
