"""SurfaceSpec.from_tree: the spec of a tree built in code, without parsing its formula back."""

from __future__ import annotations

from dataclasses import replace

import pytest

from surfgen.generator.errors import GridError, SpecError
from surfgen.generator.formula.expr import to_string
from surfgen.generator.formula.parser import parse
from surfgen.generator.model.sampler import SamplerConfig, draw_equation
from surfgen.generator.model.spec import SurfaceSpec


@pytest.mark.parametrize("family", ["sculpture", "lattice", "infill", "assembly", "twist", "free"])
def test_from_tree_is_the_spec_of_the_printed_formula(family: str) -> None:
    cfg = replace(SamplerConfig(), family=family)
    for index in range(8):
        draw = draw_equation(3, index, cfg)
        tree = draw.equation.with_d(draw.d or 0.25).to_tree()
        kw = {"provenance": {"seed": 3, "index": index}, "level": 0.5}
        fast = SurfaceSpec.from_tree(tree, draw.box.bounds(), (16, 17, 18), **kw)
        parsed = SurfaceSpec(to_string(tree), draw.box.bounds(), (16, 17, 18), **kw)
        assert fast == parsed and fast.key == parsed.key and fast.to_json() == parsed.to_json()
        assert parse(fast.formula) == tree  # the printer is the parser's fixed point here


def test_from_tree_checks_what_the_constructor_checks() -> None:
    tree = parse("x^2 + y^2 + z^2 - r", {"r"})
    with pytest.raises(SpecError, match="'r' has no value"):
        SurfaceSpec.from_tree(tree, (-1, 1, -1, 1, -1, 1), (8, 8, 8))
    with pytest.raises(SpecError, match="'s' is not used"):
        SurfaceSpec.from_tree(tree, (-1, 1, -1, 1, -1, 1), (8, 8, 8), params={"r": 1, "s": 2})
    with pytest.raises(GridError, match="xmin must be less than xmax"):
        SurfaceSpec.from_tree(tree, (1, -1, -1, 1, -1, 1), (8, 8, 8), params={"r": 1})
    spec = SurfaceSpec.from_tree(tree, (-1, 1, -1, 1, -1, 1), (8, 8, 8), params={"r": 1})
    assert dict(spec.params) == {"r": 1.0} and spec.formula == "x^2+y^2+z^2-r"
