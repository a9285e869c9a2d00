"""A sum's ``U cos θ + V sin θ`` bounded as one wave
(:mod:`surfgen.generator.eval.interval_harmonic`): the pairs found, the pair's range exact and sound, the rounding margin needed, fewer leaves
sampled for a twist with the same mesh."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from surfgen.generator.eval import interval_harmonic, interval_poly
from surfgen.generator.eval.interval_harmonic import pair_range, sum_bounds, sum_terms
from surfgen.generator.eval.interval_poly import polynomial_structure
from surfgen.generator.eval.tape import points_evaluator
from surfgen.generator.formula.parser import parse
from surfgen.generator.model.sampler import SamplerConfig, draw_equation
from tests.support.interval_checks import (
    assert_fewer_leaves_than_without,
    assert_sound,
    random_boxes,
    structure_bounds,
    twist_case,
)

LOBES = "(x^2*y+x*y^2+y^3)"
BODY = "(x^2+y^2+x*y*z+z^2-1)"


def wave(text: str):
    """``text``'s sum read by :func:`sum_terms` (its spec, the kids as strings), or None."""
    found = sum_terms(parse(text))
    return None if found is None else (found[0], [str(k) for k in found[1]])


def test_pairs_are_found_with_their_signs() -> None:
    """``U cos θ`` pairs with ``V sin θ`` of an equal θ, either factor first, either sign;
    a lone cosine, two angles that differ or a product of both waves is no pair."""
    spec, kids = wave(f"x^2*y^2+{LOBES}*cos(3*z)-sin(3*z)*(x*y)+z")
    assert spec == (("one", 1), ("pair", 1, -1), ("one", 1))
    assert kids[1:4] == [str(parse(LOBES)), "x*y", "3*z"]
    spec, _ = wave(f"-{LOBES}*sin(2*x+1)+x^2*y^2-x*cos(2*x+1)")
    assert spec == (("one", 1), ("pair", -1, 1))  # -P*sin reads (-P)*sin
    for text in [
        f"{BODY}+{LOBES}*cos(3*z)",
        f"{BODY}+{LOBES}*cos(3*z)+x*sin(3.5*z)",
        f"{BODY}+cos(z)*sin(z)",
        f"{LOBES}*cos(z)*sin(z)",
    ]:
        assert wave(text) is None, text


def test_a_twist_reads_its_lobes_as_a_pair() -> None:
    """The twist family's lobes ``P₁/D cos(ωz) + P₂/D sin(ωz)`` become one pair of the
    formula's sum in its structure, its body one polynomial term beside it."""
    cfg = SamplerConfig(family="twist")
    found = []
    for index in range(12):
        tree = draw_equation(5, index, cfg).equation.with_d(0.0).to_tree()
        structure = polynomial_structure(tree)
        if structure is not None and structure.nodes[-1][0] == "sum":
            found.append(structure.nodes[-1][1])
    assert len(found) >= 6
    for spec in found:
        assert any(entry[0] == "pair" for entry in spec)


PROPERTY = settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))
ends = st.floats(-50, 50)


@PROPERTY
@given(ends, st.floats(0, 5), ends, st.floats(0, 5), st.floats(-1e3, 1e3), st.floats(0, 8),
       st.integers(0, 2**32 - 1))  # fmt: skip
def test_the_pair_range_is_sound_and_exact(u0, du, v0, dv, t0, dt, seed) -> None:
    """Property: ``u cos θ + v sin θ`` at random points of ``[u] × [v] × [θ]`` is within
    :func:`pair_range`, and its range there is attained (up to the small widening) at a corner
    of ``[u] × [v]``, at an end of ``[θ]`` or at that corner's extreme angles within."""
    rng = np.random.default_rng(seed)
    u, v, t = (u0, u0 + du), (v0, v0 + dv), (t0, t0 + dt)
    lo, hi = (
        float(e[0]) for e in pair_range(*((np.array([a]), np.array([b])) for a, b in (u, v, t)))
    )
    inner = [rng.uniform(*r, 2000) for r in (u, v, t)]
    f_inner = inner[0] * np.cos(inner[2]) + inner[1] * np.sin(inner[2])
    f_corners = []
    for uc in u:
        for vc in v:
            turns = np.arange(np.floor((t0 - 4) / np.pi), np.ceil((t0 + dt + 4) / np.pi) + 1)
            crit = np.arctan2(vc, uc) + turns * np.pi
            ts = np.concatenate([t, crit[(crit >= t[0]) & (crit <= t[1])]])
            f_corners.append(uc * np.cos(ts) + vc * np.sin(ts))
    f = np.concatenate([f_inner, *f_corners])
    room = 1e-9 * (1 + np.hypot(max(map(abs, u)), max(map(abs, v)))) * (1 + abs(t0) + dt)
    assert lo <= f.min() and f.max() <= hi
    assert f.min() - lo <= room and hi - f.max() <= room


def sum_bounds_of(text: str):
    """``text``'s structured bounds (:func:`structure_bounds`), its last node a sum of waves."""
    tree, program, bounds = structure_bounds(text)
    assert polynomial_structure(tree).nodes[-1][0] == "sum"
    return tree, program, bounds


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_sums_with_pairs_are_sound(seed: int) -> None:
    """Bounds of sums holding pairs (polynomial factors, an angle that is a part of its own
    with poles, terms of 1e8) hold every value at random boxes' points."""
    texts = [
        f"{BODY}+{LOBES}/({BODY}^2+0.1)*cos(4.9*z)+sin(4.9*z)*((x*y^2-x^3)/({BODY}^2+0.1))",
        f"1e8*{LOBES}-x*cos(tan(y)+z)-{BODY}*sin(tan(y)+z)-1e8*{LOBES}",
        f"{BODY}-{LOBES}*sin(3*x*y)+abs(z)^1.5-{LOBES}*cos(3*x*y)",
    ]
    rng = np.random.default_rng(seed)
    for text in texts:
        tree, program, bounds = sum_bounds_of(text)
        for half in (0.05, 0.5, 3.0):
            blo, bhi = random_boxes(rng, [-half] * 3, [half] * 3, 60)
            assert_sound(tree, {}, blo, bhi, rng, bounds(program, blo, bhi))


def test_without_the_rounding_margin_the_bounds_fail(monkeypatch) -> None:
    """The margin is needed: beside terms of 1e16 the evaluator rounds each half of the pair
    away (its sum 0), while the pair's exact value, 1.84, added once rounds up to 2."""
    x, y, z = 1.3, np.pi / 4, 1.3
    value = points_evaluator(parse("1e16+x*cos(y)+z*sin(y)-1e16"), {})(
        np.array([x]), np.array([y]), np.array([z])
    )[0]
    assert value == 0.0
    spec = sum_terms(parse("1e16+x*cos(y)+z*sin(y)-1e16"))[0]
    vals = [(np.array([a]), np.array([a])) for a in (1e16, x, z, y, 1e16)]
    lo, hi = sum_bounds(spec, vals)
    assert lo[0] <= value <= hi[0]
    monkeypatch.setattr(interval_harmonic, "_UNIT", 0.0)
    lo, hi = sum_bounds(spec, vals)
    assert lo[0] > value


def test_a_twist_samples_fewer_leaves_for_the_same_mesh(monkeypatch) -> None:
    """A twist draw at an odd grid in a shifted box: fewer leaves sampled with its pairs than
    with its terms bounded apart, the same kept, and the mesh the dense path's, bit for bit."""
    tree, box, shape = twist_case()
    assert_fewer_leaves_than_without(tree, box, shape, monkeypatch, interval_poly, "sum_terms",
                                     lambda node, whole=(): None)  # fmt: skip
