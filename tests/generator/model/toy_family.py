"""A sampler family added in one module and one entry (issue 39): ``toy``, a ball of a drawn
radius, ``x² + y² + z² - r²``, in a box with a margin; its keys are ``[sampler.toy]``.

The test that uses it registers :data:`FAMILY` (``registered(FAMILY)``): nothing else in
surfgen changes for a new family.
"""

from __future__ import annotations

from dataclasses import dataclass

from surfgen.generator.errors import SpecError
from surfgen.generator.eval.grid import Box
from surfgen.generator.model.draw import Draw, DrawSettings, Family, only_a, rng_for, round_to
from surfgen.generator.model.equation13 import Equation13, PowerFunction, PowerTerm
from surfgen.generator.model.settings import require_low_high


@dataclass(frozen=True)
class ToySettings:
    """The ``[sampler.toy]`` table."""

    radius: tuple[float, float] = (0.5, 1.5)  # the ball's radius is drawn from this range
    margin: float = 1.25  # box half-size / radius

    def __post_init__(self) -> None:
        require_low_high(self, ("radius",), "sampler.toy")
        if not self.radius[0] > 0:
            raise SpecError("config [sampler.toy]: radius must be > 0")
        if not self.margin > 1:
            raise SpecError(f"config [sampler.toy]: margin must be > 1, got {self.margin}")


def draw_toy(seed: int, index: int, cfg: DrawSettings, s: ToySettings) -> Draw:
    """A ball: a pure function of ``(seed, index, config)``; d is chosen here (r²)."""
    r = round_to(rng_for(seed, index).uniform(*s.radius))
    squares = PowerFunction(
        tuple(PowerTerm(1.0, *(2.0 * (j == k) for j in range(3))) for k in range(3))
    )
    equation = Equation13(((only_a(squares),),), 0.0)
    box = Box.cube(round_to(r * s.margin))
    return Draw(equation, box, None, "toy", {"radius": r}, d=round_to(r * r, 4))


FAMILY = Family("toy", draw_toy, "a ball of a drawn radius (a test's family)", ToySettings)
