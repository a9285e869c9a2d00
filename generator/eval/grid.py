"""Boxes and grids: where a formula is sampled.

Grid points include both ends, as in K3DSurf and MathMod:
``x_i = xmin + i*(xmax - xmin)/(Nx - 1)`` for ``i = 0..Nx-1`` (never ``np.arange``).
A field sampled on a grid has shape ``(Nx, Ny, Nz)``, index order x, y, z.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from surfgen.generator.errors import GridError

MIN_POINTS = 4
MAX_POINTS = 2048
# Box bounds lie within +-MAX_COORDINATE (the sampler's box_half has the same bound): areas and
# volumes of meshes in such a box stay far from overflow.
MAX_COORDINATE = 1e6
# Grid points are at least this fraction of their distance from 0 apart, so that mesh files,
# which store float32 coordinates (24 bits), still place a vertex within 1/16 of a cell.
MIN_RELATIVE_SPACING = 2.0**-20


@dataclass(frozen=True, slots=True)
class Box:
    """An axis-aligned box ``[lo[k], hi[k]]`` for k = x, y, z."""

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]

    def __post_init__(self) -> None:
        for axis, a, b in zip("xyz", self.lo, self.hi, strict=True):
            if not (math.isfinite(a) and math.isfinite(b)):
                raise GridError(f"box: the {axis} bounds must be finite numbers, got {a}, {b}")
            if not a < b:
                raise GridError(f"box: {axis}min must be less than {axis}max, got {a} >= {b}")
            if max(abs(a), abs(b)) > MAX_COORDINATE:
                raise GridError(
                    f"box: the {axis} bounds must lie within ±{MAX_COORDINATE:.0f}, got {a!r}, {b!r}"
                )

    @classmethod
    def cube(cls, half: float) -> Box:
        return cls((-half,) * 3, (half,) * 3)

    @classmethod
    def from_bounds(cls, bounds: Sequence[float]) -> Box:
        """From ``(lo, hi)`` (the same for every axis) or ``(xmin, xmax, ymin, ymax, zmin, zmax)``."""
        b = [float(v) for v in bounds]
        if len(b) == 2:
            return cls((b[0],) * 3, (b[1],) * 3)
        if len(b) == 6:
            return cls((b[0], b[2], b[4]), (b[1], b[3], b[5]))
        raise GridError(
            f"box takes 2 numbers (lo,hi) or 6 (xmin,xmax,ymin,ymax,zmin,zmax), got {len(b)}"
        )

    def bounds(self) -> tuple[float, ...]:
        """``(xmin, xmax, ymin, ymax, zmin, zmax)``."""
        return (self.lo[0], self.hi[0], self.lo[1], self.hi[1], self.lo[2], self.hi[2])

    @property
    def size(self) -> tuple[float, float, float]:
        return tuple(b - a for a, b in zip(self.lo, self.hi, strict=True))  # type: ignore[return-value]


@dataclass(frozen=True, slots=True)
class Grid:
    """A box sampled at ``shape = (Nx, Ny, Nz)`` points, both ends included."""

    box: Box
    shape: tuple[int, int, int]

    def __post_init__(self) -> None:
        if len(self.shape) != 3:
            raise GridError(f"grid needs 3 sizes Nx,Ny,Nz, got {len(self.shape)}")
        for axis, n in zip("xyz", self.shape, strict=True):
            if int(n) != n or not MIN_POINTS <= n <= MAX_POINTS:
                raise GridError(
                    f"grid: N{axis} must be a whole number from {MIN_POINTS} to {MAX_POINTS}, got {n}"
                )
        object.__setattr__(self, "shape", tuple(int(n) for n in self.shape))
        for axis, a, b, n in zip("xyz", self.box.lo, self.box.hi, self.shape, strict=True):
            far = max(abs(a), abs(b))
            if (b - a) / (n - 1) < MIN_RELATIVE_SPACING * far:
                raise GridError(
                    f"grid: {n} points over {axis} in [{a!r}, {b!r}] are {(b - a) / (n - 1):.3g} "
                    f"apart, less than 1/{round(1 / MIN_RELATIVE_SPACING)} of their distance "
                    f"from 0 ({far!r}): too fine for mesh files, which store float32 coordinates "
                    "(7 digits); use fewer points, a wider range or one nearer 0"
                )

    @classmethod
    def from_sizes(cls, box: Box, sizes: int | Sequence[int]) -> Grid:
        if isinstance(sizes, int):
            return cls(box, (sizes,) * 3)
        s = list(sizes)
        if len(s) == 1:
            s = s * 3
        return cls(box, tuple(s))  # type: ignore[arg-type]

    @property
    def spacing(self) -> tuple[float, float, float]:
        return tuple(  # type: ignore[return-value]
            (b - a) / (n - 1) for a, b, n in zip(self.box.lo, self.box.hi, self.shape, strict=True)
        )

    @property
    def size(self) -> int:
        return self.shape[0] * self.shape[1] * self.shape[2]

    def axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The 1-D coordinates of each axis, ``x_i = lo + i*(hi - lo)/(N - 1)``."""
        out = []
        for a, b, n in zip(self.box.lo, self.box.hi, self.shape, strict=True):
            i = np.arange(n, dtype=np.float64)  # indices only; the points come from the formula
            out.append(a + i * ((b - a) / (n - 1)))
        return tuple(out)  # type: ignore[return-value]

    def open_axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The axes shaped ``(Nx,1,1)``, ``(1,Ny,1)``, ``(1,1,Nz)`` for broadcasting."""
        x, y, z = self.axes()
        return x[:, None, None], y[None, :, None], z[None, None, :]


@dataclass(frozen=True, slots=True)
class Field:
    """Samples of a formula on a grid: ``values`` has shape ``grid.shape`` and is read-only."""

    grid: Grid
    values: np.ndarray

    def __post_init__(self) -> None:
        if self.values.shape != self.grid.shape:
            raise GridError(
                f"field shape {self.values.shape} does not match grid {self.grid.shape}"
            )
        if self.values.flags.writeable:
            v = self.values.view()
            v.flags.writeable = False
            object.__setattr__(self, "values", v)

    @property
    def nonfinite(self) -> int:
        """How many samples are NaN or infinite."""
        return int(self.values.size - np.count_nonzero(np.isfinite(self.values)))
