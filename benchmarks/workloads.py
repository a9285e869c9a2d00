"""The formulas the evaluation benchmarks time: eq. (13) drawn at random, by the sampler, or
the 50 stored for the field-hash test (``tests/support/data/eq13_formulas.jsonl``)."""

from __future__ import annotations

import json

import numpy as np

from benchmarks.harness import ROOT
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.formula.expr import Expr
from surfgen.generator.formula.parser import parse
from surfgen.generator.model import equation13 as eq
from surfgen.generator.model.sampler import SamplerConfig, choose_d, draw_equation


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
