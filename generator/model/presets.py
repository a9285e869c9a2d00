"""The paper's worked examples (equations A, B, C; Figures 2-4) and classic surfaces, as presets.

The formulas are transcribed exactly as printed, oddities included:

- Equation A, Figure 2: the caption gives I1: m = 0.851 and I2: m = 0.861 (the running text says
  the opposite); we follow the caption.
- Equation B: every beta divides by ``cos(0.1 y)`` (also beta_x and beta_z), the numerators carry
  ``|y|^2``, ``|z|^2``, ``|x|^2``, and the denominators are ``x^2 y^2 + z^2``, ``x^2 + y^2 z^2``,
  ``y^2 + x^2 z^2`` as printed.
- Equation C: ``x^-1`` inside the first cosine and ``x^3`` (not ``x^2``) in the last bracket.
  The paper gives no box for it (see :data:`EQ_C_BOX`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

from surfgen.generator.errors import SpecError
from surfgen.generator.model.spec import SurfaceSpec

# ----------------------------------------------------------------------------- equation A


EQ_A_B = "(abs({v})^0.3/abs(cot(m*{v})))^0.3"  # B_x of equation A, with {v} for x, y or z


def eq_a_formula(
    b_form: str = EQ_A_B, sign: str = "-", shift_in: str = "-600", shift_out: str = "+100"
) -> str:
    """Equation A; the defaults give it as printed. The arguments exist for the readings of
    Figure 2 that ``surfgen reproduce`` investigates (the B term, the sign before 0.51, the
    constants)."""
    denom = "abs(abs(x)^1.3+abs(y)^1.3+abs(z)^1.3)"

    def a(v: str) -> str:
        return f"atan(tan(1-abs({v})^0.31+5.76*abs({v})^1.38/{denom}))^3"

    def b(v: str) -> str:
        return b_form.format(v=v)

    return (
        f"(abs(x)^3.3+abs(y)^3.3+abs(z)^3.3{shift_in})"
        f"+({a('x')}+{a('y')}+{a('z')})^3"
        f"{sign}0.51*({b('x')}+{b('y')}+{b('z')})^3{shift_out}"
    )


# ----------------------------------------------------------------------------- equation B


def _eq_b() -> str:
    alpha = "1/24.4*(x^2+y^2+z^2-5)*(abs(x)^0.13*abs(y)^0.13*abs(z)^0.13-5)"

    def beta(v: str, numer: str, denom: str) -> str:
        return f"abs(cos(2*{v}))*atan(tan(12*({numer})/({denom})))^2*cos(0.1*y)^(-1)"

    bx = beta("x", "x^2+abs(y)^2+z^2", "x^2*y^2+z^2")
    by = beta("y", "y^2+abs(z)^2+x^2", "x^2+y^2*z^2")
    bz = beta("z", "z^2+abs(x)^2+y^2", "y^2+x^2*z^2")
    return f"{alpha}+({bx}+{by}+{bz})^3-0.135"


# ----------------------------------------------------------------------------- equation C

EQ_C = (
    "(abs(cos(0.7*m*x^(-1)))/cos(0.003*x^2))^10"
    "+abs(sin(0.7*m*y))^10*abs(sin(0.7*m*z))^10/(cos(0.003*y^2)^10*cos(0.003*z^2)^10)"
    "-0.02*(x^3+y^2+z^2)"
)
# The paper prints no box for equation C. The walls where |sin(0.7 m y)|, |sin(0.7 m z)| are
# large repeat every pi/(0.7 m) (4.5 for m = 1, 18 for m = 0.25) and the cubic term
# -0.02 x^3 closes the shape towards +x; [-6, 6]^3 holds one full cell of the pattern for
# m = 1 and shows how the cell opens up as m decreases, while staying clear of the poles of
# 1/cos(0.003 u^2) at |u| = 22.9.
EQ_C_BOX = (-6.0, 6.0)
EQ_C_GRID = 64


@dataclass(frozen=True)
class Preset:
    """A named shape: formula, default parameters, box, grid, and where it comes from."""

    name: str
    formula: str
    box: tuple[float, ...]
    grid: tuple[int, int, int]
    params: Mapping[str, float] = field(default_factory=dict)
    source: str = ""
    cap: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "params", MappingProxyType(dict(self.params)))
        if len(self.box) == 2:
            object.__setattr__(self, "box", tuple(self.box) * 3)

    def spec(self, params: Mapping[str, float] | None = None) -> SurfaceSpec:
        """The preset as a spec, with ``params`` overriding its defaults."""
        unknown = sorted(set(params or {}) - set(self.params))
        if unknown:
            allowed = ", ".join(self.params) or "none"
            raise SpecError(
                f"preset {self.name} has no parameter '{unknown[0]}' (parameters: {allowed})"
            )
        return SurfaceSpec(
            formula=self.formula,
            box=self.box,
            grid=self.grid,
            params={**self.params, **(params or {})},
            provenance={"preset": self.name},
        )

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "formula": self.spec().formula,
            "box": list(self.box),
            "grid": list(self.grid),
            "params": dict(self.params),
            "cap": self.cap,
            "source": self.source,
        }


def _cube(n: int) -> tuple[int, int, int]:
    return (n, n, n)


_EQ_A, _EQ_B = eq_a_formula(), _eq_b()
_EQ_A_B1 = eq_a_formula(b_form="abs({v})^0.3/abs(cot(m*{v}))")
_A_BOX, _B_BOX = (-155.0, 155.0), (-7.0, 7.0)

_PRESETS: list[Preset] = [
    Preset("eqA", _EQ_A, _A_BOX, _cube(82), {"m": 0.861}, "paper, equation A (section 4.a.1)"),
    Preset("I1", _EQ_A, _A_BOX, _cube(82), {"m": 0.851}, "paper, Figure 2, I1: eq. A, m=0.851"),
    Preset("I2", _EQ_A, _A_BOX, _cube(82), {"m": 0.861}, "paper, Figure 2, I2: eq. A, m=0.861"),
    # Figure 2 read with B = |x|^0.3/|cot(m x)| (the outer ^0.3 dropped): the one reading that
    # `surfgen reproduce` found to make I1 and I2 differ as the paper says (docs/guide/paper.md).
    Preset(
        "I1-b1",
        _EQ_A_B1,
        _A_BOX,
        _cube(82),
        {"m": 0.851},
        "Figure 2, I1 read as B=|x|^0.3/|cot(m x)|",
    ),
    Preset(
        "I2-b1",
        _EQ_A_B1,
        _A_BOX,
        _cube(82),
        {"m": 0.861},
        "Figure 2, I2 read as B=|x|^0.3/|cot(m x)|",
    ),
    Preset("eqB", _EQ_B, _B_BOX, _cube(34), {}, "paper, equation B (section 4.a.2)"),
    Preset("I3", _EQ_B, _B_BOX, _cube(34), {}, "paper, Figure 3, I3: eq. B, box ±7, grid 34³"),
    Preset("I4", _EQ_B, (-7.05, 7.05), _cube(34), {}, "paper, Figure 3, I4: box ±7.05, grid 34³"),
    Preset("I5", _EQ_B, (-7.05, 7.05), _cube(33), {}, "paper, Figure 3, I5: box ±7.05, grid 33³"),
    Preset("eqC", EQ_C, EQ_C_BOX, _cube(EQ_C_GRID), {"m": 1.0}, "paper, equation C (4.b)"),
    *[
        Preset(
            f"C-m{m:g}",
            EQ_C,
            EQ_C_BOX,
            _cube(EQ_C_GRID),
            {"m": m},
            f"paper, Figure 4: eq. C, m={m:g}",
        )
        for m in (0.25, 0.5, 0.75, 1.0)
    ],
    Preset("sphere", "x^2+y^2+z^2-1", (-1.5, 1.5), _cube(48), {}, "unit sphere (genus 0)"),
    Preset(
        "torus",
        "(sqrt(x^2+y^2)-1)^2+z^2-0.16",
        (-1.6, 1.6),
        _cube(48),
        {},
        "torus R=1, r=0.4 (genus 1)",
    ),
    Preset(
        "gyroid",
        "sin(x)*cos(y)+sin(y)*cos(z)+sin(z)*cos(x)",
        (-5.0, 5.0),
        _cube(64),
        {},
        "Schoen's gyroid (triply periodic; cut by the box, use --cap to close it)",
        cap=True,
    ),
    Preset(
        "klein",
        "(x^2+y^2+z^2+2*y-1)*((x^2+y^2+z^2-2*y-1)^2-8*z^2)+16*x*z*(x^2+y^2+z^2-2*y-1)",
        (-3.2, 3.2),
        _cube(64),
        {},
        "Klein bottle, figure-8 immersion (K3DSurf's classic implicit form)",
    ),
    Preset(
        "clebsch",
        "81*(x^3+y^3+z^3)-189*(x^2*y+x^2*z+y^2*x+y^2*z+z^2*x+z^2*y)+54*x*y*z"
        "+126*(x*y+x*z+y*z)-9*(x^2+y^2+z^2)-9*(x+y+z)+1",
        (-1.2, 1.2),
        _cube(64),
        {},
        "Clebsch diagonal cubic surface (27 real lines)",
        cap=True,
    ),
    Preset(
        "schwarz",
        "cos(x)+cos(y)+cos(z)",
        (-4.0, 4.0),
        _cube(64),
        {},
        "Schwarz P minimal surface (approximation)",
        cap=True,
    ),
    Preset(
        "chmutov",
        "(32*x^6-48*x^4+18*x^2-1)+(32*y^6-48*y^4+18*y^2-1)+(32*z^6-48*z^4+18*z^2-1)",
        (-1.1, 1.1),
        _cube(64),
        {},
        "Chmutov surface of degree 6: T6(x)+T6(y)+T6(z)=0 (Chebyshev polynomials)",
    ),
]

PRESETS: dict[str, Preset] = {p.name: p for p in _PRESETS}


def get_preset(name: str) -> Preset:
    """The preset called ``name``; :class:`SpecError` listing the names otherwise."""
    try:
        return PRESETS[name]
    except KeyError:
        raise SpecError(f"unknown preset '{name}' (presets: {', '.join(PRESETS)})") from None
