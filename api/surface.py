"""A shape as a Python value: :class:`Surface`, a :class:`~surfgen.generator.model.spec.SurfaceSpec`
and how it is meshed, with its field, mesh, metrics and verdict on demand.

The evaluator, the mesher and the filters (numba, scikit-image, trimesh, pymeshlab) are imported
by the methods that use them, so that ``import surfgen`` (and the CLI's light commands, which
import it) load none of them.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from surfgen.display import facts_html, picture, png_of, shorten, to_trimesh
from surfgen.generator.errors import FormulaError, SpecError, SurfgenError
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Field, Grid
from surfgen.generator.formula.limits import (
    MAX_SPEC_FILE_BYTES,
    MemoryBudget,
    estimate_memory,
    read_text_file,
)
from surfgen.generator.interop.mathmod import load_model, parse_script, read_script
from surfgen.generator.model.presets import get_preset
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.run.config import Config
from surfgen.settings import ConfigLike, Walls, run_config

if TYPE_CHECKING:
    import trimesh
    from PIL import Image

    from surfgen.generator.mesh.realise import Realised
    from surfgen.generator.model.draw import Draw

GridLike = int | Sequence[int]
"""Points per axis, both ends included: ``N`` for ``N × N × N``, or ``(Nx, Ny, Nz)``."""


@dataclass(frozen=True)
class Check:
    """The filters' verdict on a surface, as a sampling run reaches it.

    Attributes
    ----------
    accepted : bool
        Whether ``surfgen sample`` would keep the shape (before the near-duplicate check).
    reasons : tuple of str
        Why not (``surfgen.filters.verdict.REASONS``), empty when accepted.
    metrics : dict
        What the checks measured on the way, rounded as the catalogue stores them (all the
        catalogue's metrics for an accepted shape).
    """

    accepted: bool
    reasons: tuple[str, ...]
    metrics: dict[str, Any]

    def __bool__(self) -> bool:
        return self.accepted

    def __repr__(self) -> str:
        if self.accepted:
            return f"Check(accepted, {len(self.metrics)} metrics)"
        return f"Check(rejected: {', '.join(self.reasons)})"


@dataclass(frozen=True, eq=False)
class Surface:
    """One shape: its spec and how it is meshed by default.

    Make one with :meth:`from_formula`, :meth:`from_preset`, :meth:`from_mathmod`,
    :meth:`from_spec` or :func:`surfgen.draw`; a catalogue's records have one
    (:attr:`surfgen.Record.surface`). Two surfaces are equal when their specs and mesh
    options are.

    Attributes
    ----------
    spec : SurfaceSpec
        Formula, parameters, box, grid, level and provenance.
    cap : bool
        Close the surface where the box cuts it, by default (a preset's own choice; a run's
        ``[run] cap`` for drawn and catalogued shapes).
    walls : {None, 'keep', 'remove', 'mark'}
        The default of :meth:`mesh`: None meshes without classifying the crossings (the same
        faces as ``keep``); a run's ``[run] walls`` when not ``keep``.
    config : Config or None
        The run's config for drawn and catalogued shapes: :meth:`check` judges with it.
    """

    spec: SurfaceSpec
    cap: bool = False
    walls: Walls | None = None
    config: Config | None = None
    # The sampler's draw and its d (drawn shapes): a sculpture's envelope for the checks.
    _draw: Draw | None = field(default=None, repr=False, kw_only=True)
    _d: float | None = field(default=0.0, repr=False, kw_only=True)
    # The field and mesh of the pictures (a notebook draws them twice: PNG and HTML).
    _made: dict[tuple[Any, ...], Realised] = field(default_factory=dict, repr=False, init=False)

    # -- making one --------------------------------------------------------------------------

    @classmethod
    def from_formula(
        cls,
        formula: str,
        *,
        box: Sequence[float] = (-2.0, 2.0),
        grid: GridLike = 64,
        params: Mapping[str, float] | None = None,
        level: float = 0.0,
        cap: bool = False,
    ) -> Surface:
        """The surface ``formula = level`` in ``box``.

        Parameters
        ----------
        formula : str
            K3DSurf/MathMod syntax in ``x``, ``y``, ``z`` and named parameters
            (``docs/reference/formula.md``); inside is ``F < level``.
        box : sequence of float
            ``(lo, hi)`` for a cube or ``(xmin, xmax, ymin, ymax, zmin, zmax)``.
        grid : int or sequence of int
            Points per axis, both ends included: ``N`` or ``(Nx, Ny, Nz)``.
        params : mapping of str to float, optional
            A value for each named parameter of the formula.
        level : float
            The iso level.
        cap : bool
            Close the surface where the box cuts it (the default of :meth:`mesh`).

        Raises
        ------
        FormulaSyntaxError
            The formula does not parse (the message names the column).
        SpecError, GridError
            A parameter without value (or unused), a bad box or grid.
        """
        spec = _build(formula=formula, params=params, box=box, grid=grid, level=level)
        return cls(spec, cap=cap)

    @classmethod
    def from_preset(
        cls,
        name: str,
        *,
        params: Mapping[str, float] | None = None,
        box: Sequence[float] | None = None,
        grid: GridLike | None = None,
        level: float | None = None,
        cap: bool | None = None,
    ) -> Surface:
        """A preset (``surfgen presets``: the paper's examples, classic surfaces), with its
        parameters, box, grid and level overridden where given; ``cap`` defaults to the
        preset's own.

        Raises
        ------
        SpecError
            An unknown preset or parameter (the message lists the allowed ones).
        """
        spec = _build(preset=name, params=params, box=box, grid=grid, level=level)
        return cls(spec, cap=get_preset(name).cap if cap is None else cap)

    @classmethod
    def from_mathmod(
        cls,
        script: str | os.PathLike[str] | Mapping[str, Any],
        *,
        name: str | None = None,
        component: str | None = None,
        slider: int | None = None,
        params: Mapping[str, float] | None = None,
        grid: int | None = None,
        cap: bool = False,
    ) -> Surface:
        """An Iso3D model of a MathMod script (``surfgen render --mathmod``).

        Parameters
        ----------
        script : path, str or mapping
            A script file, its JSON text, or the decoded JSON.
        name : str, optional
            The model's ``Name`` (default: the only or first Iso3D model).
        component : str, optional
            The component's name or index; required when the model has several.
        slider : int, optional
            The slider set whose values the constants take.
        params : mapping of str to float, optional
            Values of the script's constants, overriding its own.
        grid : int, optional
            Points per axis instead of the script's ``Grid``.

        Raises
        ------
        SpecError
            Not a MathMod script, no such model or component, a parametric model.
        """
        if isinstance(script, Mapping):
            models = parse_script(json.dumps(script))
        elif isinstance(script, str) and script.lstrip().startswith("{"):
            models = parse_script(script)
        else:
            models = read_script(Path(script))
        model = load_model(models, name, slider_set=slider, params=params, grid=grid)
        if component is None and len(model.components) > 1:
            names = ", ".join(c.name for c in model.components)
            raise SpecError(
                f"model {model.name} has {len(model.components)} components ({names}): "
                "give component="
            )
        chosen = model.components[0] if component is None else model.component(component)
        return cls(chosen.spec, cap=cap)

    @classmethod
    def from_spec(
        cls, spec: SurfaceSpec | Mapping[str, Any] | str | os.PathLike[str], *, cap: bool = False
    ) -> Surface:
        """A surface from a :class:`SurfaceSpec`, its dict or JSON text, or a spec file.

        Raises
        ------
        SpecError
            A spec that is not valid (the message names the field).
        """
        if isinstance(spec, SurfaceSpec):
            return cls(spec, cap=cap)
        if isinstance(spec, Mapping):
            return cls(SurfaceSpec.from_dict(spec), cap=cap)
        if isinstance(spec, str) and spec.lstrip().startswith("{"):
            return cls(SurfaceSpec.from_json(spec), cap=cap)
        text = read_text_file(Path(spec), MAX_SPEC_FILE_BYTES, "spec file")
        return cls(SurfaceSpec.from_json(text), cap=cap)

    def with_grid(self, grid: GridLike) -> Surface:
        """The same surface on another grid (a new spec, so a new key; provenance kept)."""
        return replace(self, spec=self.spec.replace(grid=_grid_shape(grid)))

    # -- what it is ----------------------------------------------------------------------------

    @property
    def key(self) -> str:
        """The shape's key: 16 hex digits of the sha256 of the spec's canonical JSON."""
        return self.spec.key

    @property
    def formula(self) -> str:
        """The canonical formula, in K3DSurf/MathMod syntax (paste it there)."""
        return self.spec.formula

    @property
    def box(self) -> tuple[float, float, float, float, float, float]:
        """``(xmin, xmax, ymin, ymax, zmin, zmax)``."""
        return self.spec.box

    @property
    def grid(self) -> tuple[int, int, int]:
        """``(Nx, Ny, Nz)``: points per axis, both ends included."""
        return self.spec.grid

    @property
    def params(self) -> dict[str, float]:
        """The values of the formula's named parameters."""
        return dict(self.spec.params)

    @property
    def level(self) -> float:
        """The iso level: the surface is ``F = level``, inside is ``F < level``."""
        return self.spec.level

    @property
    def provenance(self) -> dict[str, Any]:
        """Where it came from: ``preset``, or ``seed``, ``index``, ``sampler``, ``config``."""
        return dict(self.spec.provenance)

    @property
    def family(self) -> str | None:
        """The sampler family of a drawn shape (None for the others)."""
        return None if self._draw is None else self._draw.family

    def to_json(self) -> str:
        """The spec's canonical JSON (what the key hashes; ``Surface.from_spec`` reads it)."""
        return self.spec.to_json()

    def to_dict(self) -> dict[str, Any]:
        """The spec as a JSON-ready dict."""
        return self.spec.to_dict()

    # -- computing -----------------------------------------------------------------------------

    def field(
        self, grid: GridLike | None = None, *, evaluator: str = "fast", threads: int | None = None
    ) -> np.ndarray:
        """The formula sampled on the grid.

        Parameters
        ----------
        grid : int or sequence of int, optional
            Another grid than the spec's (same box).
        evaluator : {'fast', 'reference'}
            The numba tape interpreter, or the plain-numpy reference (same bits).
        threads : int, optional
            Threads of the fast evaluator (default: numba's).

        Returns
        -------
        numpy.ndarray
            float64, shape ``(Nx, Ny, Nz)``, read-only; ``values[i, j, k]`` is F at
            ``x_i = xmin + i (xmax - xmin) / (Nx - 1)`` (and so for y, z). Poles and 0/0 give
            non-finite values, which count as outside.

        Raises
        ------
        FormulaError, LimitError
            What evaluation raises.
        """
        if evaluator not in ("fast", "reference"):  # sparse gives no dense array
            raise FormulaError(
                f"unknown field evaluator '{evaluator}' (allowed: fast, reference; "
                "mesh() also takes sparse and auto)"
            )
        spec = self._on(grid).spec
        sampled = evaluate(
            spec.tree(), spec.to_grid(), spec.params, evaluator=evaluator, threads=threads
        )
        values: np.ndarray = sampled.values
        return values

    def mesh(
        self,
        grid: GridLike | None = None,
        *,
        cap: bool | None = None,
        walls: Walls | None = None,
        evaluator: str = "auto",
    ) -> trimesh.Trimesh:
        """The surface ``F = level`` as a triangle mesh (marching cubes).

        Parameters
        ----------
        grid : int or sequence of int, optional
            Mesh :meth:`with_grid` ``(grid)`` instead: the metadata then name that spec.
        cap : bool, optional
            Close the surface where the box cuts it (default: :attr:`cap`).
        walls : {'keep', 'remove', 'mark'}, optional
            Classify the crossings and keep the walls (poles, jumps), remove them (open
            sheets), or mark them (face attribute ``kind``; default: :attr:`walls`).
        evaluator : {'auto', 'sparse', 'dense', 'fast', 'reference'}
            ``sparse`` evaluates only the blocks the surface may cross (interval arithmetic),
            ``dense`` or ``fast`` every grid point, ``reference`` in plain numpy; ``auto`` (default) is
            sparse on large grids (from 160^3 points). All make the same mesh, bit for bit.

        Returns
        -------
        trimesh.Trimesh
            Vertices ``(V, 3)`` float64 in box coordinates, faces ``(F, 3)`` counter-clockwise
            seen from outside; ``metadata`` holds ``key``, ``formula``, ``spec``, ``cap``,
            ``walls`` (and ``wall_fraction`` when classified). Not processed by trimesh
            (no vertex merging).

        Raises
        ------
        EmptySurface
            Nothing crosses the level in the box.
        SpecError
            An unknown walls mode.
        LimitError
            The grid needs more memory than is available: estimated before anything is
            allocated, and checked again as a sparse run learns the surface's size.
        """
        surface = self._on(grid)
        made = surface._realised(self.cap if cap is None else cap, walls or self.walls, evaluator)
        assert made.mesh is not None  # realise raises EmptySurface otherwise
        metadata: dict[str, Any] = {
            "key": surface.key,
            "formula": surface.formula,
            "spec": surface.spec.to_dict(),
            "cap": self.cap if cap is None else cap,
            "walls": walls or self.walls or "keep",
        }
        if made.walls is not None:
            metadata["wall_fraction"] = made.walls.wall_fraction
        return to_trimesh(made.mesh, metadata)

    def metrics(self, grid: GridLike | None = None, *, cap: bool | None = None) -> dict[str, Any]:
        """Everything the catalogue measures of a shape, whatever the filters would say.

        The field's ``nonfinite`` samples; the mesh's topology and geometry (``vertices``,
        ``faces``, ``components``, ``euler``, ``genus``, ``watertight``, ``boundary_edges``,
        ``nonmanifold_edges``, ``nonmanifold_vertices``, ``area``, ``volume``, ``bbox``); the
        filters' ``box_fraction``, ``largest_component_fraction``, ``total_curvature``,
        ``wall_fraction``, ``smallest_piece``; ``free_standing``, ``solidity``, ``outline``
        (every view's silhouette over its convex hull; the sampler measures it for the one-piece
        shapes of low genus of the families judged by their outline) and the symmetries; a
        sculpture's ``departure`` from its envelope. Full precision (the catalogue keeps 10
        digits).

        Raises
        ------
        EmptySurface
            Nothing crosses the level in the box.
        """
        # deferred: the filters load numba and pymeshlab
        from surfgen.filters.shape import quality_metrics
        from surfgen.filters.verdict import shape_metrics
        from surfgen.generator.mesh.outline import outline_fill
        from surfgen.generator.model.families.carving import envelope_departure

        surface = self._on(grid)
        made = surface._realised(self.cap if cap is None else cap, self.walls or "keep", "fast")
        assert made.mesh is not None and made.walls is not None
        assert isinstance(made.field, Field)  # the "fast" evaluator: every grid point
        spec = surface.spec
        out: dict[str, Any] = {"nonfinite": made.field.nonfinite}
        if self._draw is not None and self._draw.envelope is not None:
            envelope = evaluate(self._draw.envelope, spec.to_grid()).values
            out["departure"] = envelope_departure(made.field.values, envelope, spec.level)
        out.update(shape_metrics(made.mesh, spec.box))
        out["wall_fraction"] = made.walls.wall_fraction
        out.update(quality_metrics(made.mesh, out))
        out["outline"] = outline_fill(made.mesh)
        return dict(sorted(out.items()))

    def check(self, config: ConfigLike = None) -> Check:
        """The filters' verdict, as ``surfgen sample`` reaches it (coarse field, field, mesh,
        walls, topology, shape quality; the near-duplicate check needs a run).

        Parameters
        ----------
        config : Config, path or None
            Whose ``[filters]`` judge (default: the run's for drawn and catalogued shapes,
            else the default config); the surface's own :attr:`cap` and :attr:`walls` apply.

        Returns
        -------
        Check
            ``accepted``, ``reasons`` and the metrics measured.
        """
        from surfgen.pipelines.run.shapes import judge_spec  # deferred: the whole sampler

        cfg = self.config if config is None and self.config is not None else run_config(config)
        cfg = cfg.with_run(cap=self.cap, walls=self.walls or "keep")
        verdict, metrics, _ = judge_spec(self.spec, cfg, draw=self._draw, d=self._d)
        return Check(verdict.accepted, verdict.reasons, metrics)

    def thumbnail(self, size: int = 256) -> Image.Image:
        """The catalogue's picture of the mesh (shaded, the same on every machine).

        Returns
        -------
        PIL.Image.Image
            RGB, ``size`` × ``size``.

        Raises
        ------
        EmptySurface
            Nothing crosses the level in the box.
        """
        made = self._realised(self.cap, self.walls, "fast", keep=True)
        assert made.mesh is not None
        return picture(made.mesh, size)

    # -- showing -------------------------------------------------------------------------------

    def __repr__(self) -> str:
        box = ", ".join(f"{v:g}" for v in self.box)
        return (
            f"Surface(key={self.key!r}, formula={shorten(self.formula)!r}, box=({box}), "
            f"grid={self.grid}{', cap=True' if self.cap else ''})"
        )

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Surface):
            return NotImplemented
        return (self.spec, self.cap, self.walls) == (other.spec, other.cap, other.walls)

    def __hash__(self) -> int:
        return hash((self.key, self.cap, self.walls))

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        """Pickled through the spec's JSON (a data loader's workers send shapes back so), the
        field and mesh held left out."""
        state = (self.spec.to_json(), self.cap, self.walls, self.config, self._draw, self._d)
        return (_restore, state)

    def _repr_png_(self) -> bytes | None:
        """The thumbnail, for notebooks (None when there is no surface to show)."""
        try:
            return png_of(self.thumbnail())
        except SurfgenError:
            return None

    def _repr_html_(self) -> str:
        """A card for notebooks: the thumbnail and the key facts."""
        note = ""
        try:
            png: bytes | None = png_of(self.thumbnail())
        except SurfgenError as exc:
            png, note = None, f"no picture: {exc}"
        return facts_html(f"Surface {self.key}", self._facts(), png, note)

    def _facts(self) -> list[tuple[str, Any]]:
        facts: list[tuple[str, Any]] = [("formula", self.formula)]
        facts += [("box", self.box), ("grid", "×".join(map(str, self.grid)))]
        if self.params:
            facts.append(("params", self.params))
        if self.level:
            facts.append(("level", self.level))
        if self.family is not None:
            facts.append(("family", self.family))
        facts += [(k, v) for k, v in self.provenance.items() if k != "config"]
        return facts

    # -- internals -----------------------------------------------------------------------------

    def _on(self, grid: GridLike | None) -> Surface:
        return self if grid is None else self.with_grid(grid)

    def _realised(
        self, cap: bool, walls: Walls | None, evaluator: str, keep: bool = False
    ) -> Realised:
        """The field and mesh for these options: the one kept for the pictures if it is
        theirs, else made (and kept when ``keep``: a notebook shows the same mesh twice, as
        PNG and HTML, and a data loader holding many shapes must not hold their fields)."""
        # deferred: the mesher (numba)
        from surfgen.generator.mesh.realise import realise, resolve_evaluator

        key = (cap, walls, evaluator)
        if key in self._made:
            return self._made[key]
        grid = self.spec.to_grid()
        name = resolve_evaluator(evaluator, grid)
        what = f"meshing {self.key} on a {'x'.join(map(str, grid.shape))} grid ({name} evaluator)"
        # as render: the estimate before anything is allocated, then a sparse run's own checks
        parts = estimate_memory(grid.size, mesh=True, sparse=name == "sparse")
        budget = MemoryBudget.after_estimate(parts, None, what, setting=None)
        made = realise(self.spec, evaluator=evaluator, cap=cap, walls=walls, budget=budget)
        if keep:
            self._made.clear()
            self._made[key] = made
        return made


def _restore(
    spec: str,
    cap: bool,
    walls: Walls | None,
    config: Config | None,
    made: Draw | None,
    d: float | None,
) -> Surface:
    """A pickled :class:`Surface` (:meth:`Surface.__reduce__`)."""
    return Surface(SurfaceSpec.from_json(spec), cap, walls, config, _draw=made, _d=d)


def _grid_shape(grid: GridLike) -> tuple[int, int, int]:
    """``(Nx, Ny, Nz)`` of ``N`` or a sequence of 1 or 3 whole numbers (GridError otherwise)."""
    sizes = [grid] if isinstance(grid, int) else list(grid)
    return Grid.from_sizes(Box.cube(1), sizes).shape


def _build(
    *,
    formula: str | None = None,
    preset: str | None = None,
    params: Mapping[str, float] | None,
    box: Sequence[float] | None,
    grid: GridLike | None,
    level: float | None,
) -> SurfaceSpec:
    """The spec of a formula or preset, as ``surfgen render`` builds it (one function)."""
    # deferred: the render module holds the mesh writers (numba, trimesh)
    from surfgen.pipelines.export.render import build_spec

    sizes = None if grid is None else ([grid] if isinstance(grid, int) else list(grid))
    return build_spec(
        preset=preset,
        formula=formula,
        params=dict(params or {}),
        box=None if box is None else list(box),
        grid=sizes,
        level=level,
    )
