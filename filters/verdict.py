"""Filters: is a sampled shape worth keeping? Each rejection names its reason.

Two stages (see docs/guide/sampling.md):

- :func:`screen_field` looks at a sampled field (cheap): too many non-finite samples, no inside
  or no outside, or signs that flip between most neighbours (noise);
- :func:`judge` looks at the mesh's metrics (:func:`shape_metrics`): non-empty, manifold,
  and complex enough but not speckle.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np

from surfgen.filters.geometry import corner_angle_sums, used_mask
from surfgen.filters.meshlab import face_components
from surfgen.filters.metrics import measure_mesh
from surfgen.generator.errors import SpecError
from surfgen.generator.jit.options import CHECKED
from surfgen.generator.mesh.mesh import Mesh, face_areas
from surfgen.generator.model.settings import (
    require_fractions,
    settings_from_mapping,
    settings_to_dict,
)

REASONS = (
    "no_crossing",  # no d gives a surface (the sum is constant or non-finite on the coarse grid)
    "nonfinite",  # too many NaN/inf samples
    "noise",  # signs flip between most neighbours
    "empty",  # (almost) nothing inside
    "full",  # (almost) everything inside
    "too_small",  # too few faces
    "nonmanifold",  # non-manifold edges or vertices after repair
    "not_watertight",  # open, although capped
    "speckle",  # too many components, or no dominant one
    "fragmented",  # drawn as one body, broken into pieces; or bodies with flying debris
    "box_dominated",  # mostly the caps on the box faces
    "blob",  # only convex lumps (plates, slabs, smooth blobs)
    "plain",  # a lump: its envelope barely marked, or every view of it a convex outline
    "too_complex",  # genus beyond the limit
    "walls",  # too much of the area is walls (poles and jumps), not the zero set
    "unresolved",  # the surface changes on the nested grid twice as fine (aliasing)
    "duplicate",  # the same formula and grid is already in the catalogue
    "timeout",  # took longer than the run's timeout
    "crashed",  # its worker process died or raised an unexpected error
)


@dataclass(frozen=True)
class FilterConfig:
    """Thresholds of the ``[filters]`` table (see ``surfgen config show``)."""

    coarse_grid: int = 24
    max_nonfinite_fraction: float = 0.5
    max_flip_fraction: float = 0.15
    min_inside_fraction: float = 0.003
    max_inside_fraction: float = 0.75
    min_faces: int = 400
    max_components: int = 60
    min_largest_component_fraction: float = 0.2
    min_body_fraction: float = 0.8
    max_pieces: int = 8
    min_piece_fraction: float = 0.1
    max_box_fraction: float = 0.35
    max_genus: int = 500
    blob_max_curvature: float = 1.25
    plain_max_departure: float = 0.12
    plain_min_solidity: float = 0.9
    plain_max_curvature: float = 6.0
    plain_min_outline: float = 0.85
    plain_outline_max_genus: int = 7
    require_manifold: bool = True
    max_wall_fraction: float = 0.25
    check_resolution: bool = True
    resolution_band: int = 1
    max_resolution_shift: float = 0.6
    max_resolution_area: float = 1.10
    max_resolution_singular: float = 0.05

    def __post_init__(self) -> None:
        if not 4 <= self.coarse_grid <= 256:
            raise SpecError("config [filters]: coarse_grid must be from 4 to 256")
        fractions = (
            "max_nonfinite_fraction",
            "max_flip_fraction",
            "min_inside_fraction",
            "max_inside_fraction",
            "min_largest_component_fraction",
            "min_body_fraction",
            "min_piece_fraction",
            "max_box_fraction",
            "plain_max_departure",
            "plain_min_solidity",
            "plain_min_outline",
            "max_wall_fraction",
        )
        require_fractions(self, fractions, "filters")
        if not 0 <= self.resolution_band <= 8:
            raise SpecError("config [filters]: resolution_band must be from 0 to 8 (cells)")
        if not self.max_resolution_shift > 0:
            raise SpecError("config [filters]: max_resolution_shift must be > 0 (coarse cells)")
        if not self.plain_max_curvature >= 0:
            raise SpecError("config [filters]: plain_max_curvature must be >= 0 (0: off)")
        if not self.max_resolution_singular >= 0:
            raise SpecError(
                "config [filters]: max_resolution_singular must be >= 0 (samples per face)"
            )
        if not self.max_resolution_area >= 1:
            raise SpecError("config [filters]: max_resolution_area must be >= 1 (an area ratio)")
        for name in ("min_faces", "max_components", "max_genus", "plain_outline_max_genus"):
            if getattr(self, name) < 0:
                raise SpecError(f"config [filters]: {name} must be >= 0")
        if self.max_pieces < 1:
            raise SpecError(f"config [filters]: max_pieces must be >= 1, got {self.max_pieces}")

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any]) -> FilterConfig:
        return settings_from_mapping(cls, data, "filters")

    def to_dict(self) -> dict[str, Any]:
        return settings_to_dict(self)


@dataclass(frozen=True)
class Verdict:
    """``accepted`` with no reasons, or rejected with at least one reason of :data:`REASONS`."""

    accepted: bool
    reasons: tuple[str, ...] = ()

    @classmethod
    def reject(cls, *reasons: str) -> Verdict:
        return cls(False, tuple(reasons))


ACCEPT = Verdict(True)


def field_statistics(values: np.ndarray, level: float = 0.0) -> dict[str, float]:
    """Statistics of a field of shape (Nx, Ny, Nz) (non-finite samples count as outside).

    ``inside_fraction``, ``nonfinite_fraction``; ``flip_fraction``: neighbour pairs with
    opposite sides; ``box_fraction_estimate``: the share of a capped mesh's area that would lie
    on the box, from the inside samples on the grid's faces (cap area) and the sign changes
    (surface area: each crossing edge stands for about one cell face, / 1.5 for the average
    over-count of a staircase surface).
    """
    finite = np.isfinite(values)
    inside = finite & (values < level)
    flips = 0
    pairs = 0
    for axis in range(3):
        a = np.swapaxes(inside, 0, axis)
        flips += int(np.count_nonzero(a[1:] != a[:-1]))
        pairs += a[1:].size
    faces = [inside[0], inside[-1], inside[:, 0], inside[:, -1], inside[:, :, 0], inside[:, :, -1]]
    cap_cells = float(sum(np.count_nonzero(f) for f in faces))
    n = values.size
    return {
        "inside_fraction": float(np.count_nonzero(inside)) / n,
        "nonfinite_fraction": float(n - np.count_nonzero(finite)) / n,
        "flip_fraction": flips / pairs if pairs else 0.0,
        "box_fraction_estimate": cap_cells / (cap_cells + flips / 1.5) if cap_cells else 0.0,
    }


def screen_field(
    values: np.ndarray, level: float, cfg: FilterConfig, coarse: bool, capped: bool = True
) -> Verdict:
    """The cheap verdict on a field; ``coarse`` also checks for noise and clear box-domination."""
    s = field_statistics(values, level)
    if s["nonfinite_fraction"] > cfg.max_nonfinite_fraction:
        return Verdict.reject("nonfinite")
    if s["inside_fraction"] < cfg.min_inside_fraction:
        return Verdict.reject("empty")
    if s["inside_fraction"] > cfg.max_inside_fraction:
        return Verdict.reject("full")
    if coarse and s["flip_fraction"] > cfg.max_flip_fraction:
        return Verdict.reject("noise")
    # Only clear cases: the full check on the mesh decides the rest.
    if coarse and capped and s["box_fraction_estimate"] > 1.5 * cfg.max_box_fraction:
        return Verdict.reject("box_dominated")
    return ACCEPT


def quick_metrics(
    mesh: Mesh, box: tuple[float, ...], areas: np.ndarray | None = None
) -> dict[str, Any]:
    """The cheap part of :func:`shape_metrics` (numpy only): ``faces``, ``components``,
    ``box_fraction`` (share of the area on the box's faces), ``largest_component_fraction``
    (area of the largest component / total) and ``smallest_piece`` (area of the smallest
    component / the largest's: 1 for one piece, small for a body with debris).  ``areas``: the mesh's
    :func:`~surfgen.generator.mesh.mesh.face_areas`, where the caller has them already."""
    areas = face_areas(mesh) if areas is None else areas
    total = float(areas.sum()) or 1.0
    lo = np.array(box[0::2])
    hi = np.array(box[1::2])
    tol = 1e-9 * float(np.max(hi - lo))
    on_face = _on_box_faces(mesh.vertices, mesh.faces, lo, hi, tol)
    labels = face_components(mesh)
    per = np.bincount(labels, weights=areas)
    return {
        "faces": mesh.n_faces,
        "components": int(per.size),
        "box_fraction": float(areas[on_face].sum()) / total,
        "largest_component_fraction": float(per.max()) / total if per.size else 0.0,
        "smallest_piece": float(per.min() / per.max()) if per.size and per.max() > 0 else 1.0,
    }


@numba.njit(**CHECKED)
def _on_box_faces(
    v: np.ndarray, f: np.ndarray, lo: np.ndarray, hi: np.ndarray, tol: float
) -> np.ndarray:
    """(F,) bool: the faces whose three corners lie on one face of the box (within ``tol``).

    The test is per vertex (one bit per box face), so each corner is compared once instead of
    once per face around it; the comparisons are the same, so is the result.
    """
    sides = np.zeros(v.shape[0], dtype=np.uint8)
    for i in range(v.shape[0]):
        bits = 0
        for k in range(3):
            if abs(v[i, k] - lo[k]) <= tol:
                bits |= 1 << (2 * k)
            if abs(v[i, k] - hi[k]) <= tol:
                bits |= 2 << (2 * k)
        sides[i] = bits
    out = np.zeros(f.shape[0], dtype=np.bool_)
    for t in range(f.shape[0]):
        out[t] = (sides[f[t, 0]] & sides[f[t, 1]] & sides[f[t, 2]]) != 0
    return out


def shape_metrics(
    mesh: Mesh, box: tuple[float, ...], quick: Mapping[str, Any] | None = None
) -> dict[str, Any]:
    """:func:`measure_mesh` (manifoldness through pymeshlab, genus, ...), :func:`quick_metrics`
    (pass ``quick`` if they are already measured: they are not measured again),
    and ``total_curvature``: the sum over vertices of the absolute angle deficit, / 4 pi
    (1 for any convex closed surface, more for wavy ones)."""
    m = measure_mesh(mesh).to_dict()
    m.update(quick_metrics(mesh, box) if quick is None else quick)
    m["total_curvature"] = _total_abs_curvature(mesh.vertices, mesh.faces) / (4 * math.pi)
    return m


def _total_abs_curvature(v: np.ndarray, f: np.ndarray) -> float:
    """Sum of |2 pi - sum of corner angles| over vertices (discrete Gauss-Bonnet)."""
    # The corner angles and their per-vertex sums in numba, with surfgen's acos (the same bits
    # on every CPU); the final sum stays numpy's (pairwise, the same order everywhere).
    angle_sum = corner_angle_sums(v, f, len(v))
    used = used_mask(f, len(v))
    return float(np.abs(2 * math.pi - angle_sum[used]).sum())


def plain(metrics: Mapping[str, Any], cfg: FilterConfig) -> bool:
    """The envelope with barely a mark on it, by any of three measures:

    - a shape with an envelope (a sculpture) that departs from it by less than
      ``plain_max_departure`` (``departure``: the spread of the surface's offset from the
      envelope over the envelope's radius);
    - from the mesh alone, whatever the family: one closed piece that fills at least
      ``plain_min_solidity`` of its convex hull (``solidity``): a rounded box or ball with at
      most a scratch or a pinhole (its carving, if any, takes under a tenth of the hull);
    - from the mesh alone: genus 0 (one piece or a few) with a total absolute curvature
      (``total_curvature``, integral |K| / 4 pi, summed over the pieces) below
      ``plain_max_curvature``: lumps with a few dents or bulges (a pillow, a peanut, two dented
      balls, a box with a knob). A convex body has exactly 1; every saddle region adds, so
      carved, spiky, lobed and twisted shapes reach 6 and more (calibrated on contact sheets
      of seed 7: docs/guide/filters.md);
    - likewise one piece of genus 1 below ``plain_max_curvature``: a plain ring (a torus has
      exactly 2), a ring with a knob, a ball with one tunnel. Higher genera are not judged
      this way: a smooth frame or a box with tunnels has little curvature to spare, yet is
      not plain.
    - from the mesh alone: one piece of genus at most ``plain_outline_max_genus`` whose
      silhouette fills at least ``plain_min_outline`` of its convex hull in every view
      (``outline``, :mod:`surfgen.generator.mesh.outline`): a lump whose ornament only dents it, a
      lens, a gem whose facets barely change, however wavy its surface (measured only for the
      families judged by their outline: every one but ``twist``, whose grooves are its look).
    Measures that are missing are not judged."""
    departure = metrics.get("departure")
    if departure is not None and departure < cfg.plain_max_departure:
        return True
    solidity = metrics.get("solidity")
    one_piece = metrics.get("components") == 1
    if one_piece and solidity is not None and solidity >= cfg.plain_min_solidity:
        return True
    outline = metrics.get("outline")
    if outline is not None and outline >= cfg.plain_min_outline and judged_by_outline(metrics, cfg):
        return True
    curvature = metrics.get("total_curvature")
    if curvature is None or not curvature < cfg.plain_max_curvature:
        return False
    if metrics.get("genus") == 1:
        return one_piece
    # genus 0: from the blobs' bound up (a convex lump is a blob, not also plain)
    return (
        metrics.get("genus") == 0
        and cfg.blob_max_curvature * metrics.get("components", 1) <= curvature
    )


def judged_by_outline(metrics: Mapping[str, Any], cfg: FilterConfig) -> bool:
    """Whether :func:`plain` judges the shape by its ``outline``: one piece, of genus at most
    ``plain_outline_max_genus`` (the sampler measures the outline only then)."""
    genus = metrics.get("genus")
    return (
        metrics.get("components") == 1
        and genus is not None
        and genus <= cfg.plain_outline_max_genus
    )


def unresolved(metrics: Mapping[str, Any], cfg: FilterConfig) -> bool:
    """A shape whose surface moves more than ``max_resolution_shift`` coarse cells (95th
    percentile, either way) or gains more than ``max_resolution_area`` in area on the nested
    grid twice as fine (:mod:`surfgen.filters.resolution`), or whose fine grid finds more than
    ``max_resolution_singular`` new non-finite samples per face of its mesh (a pole on a plane
    such as ``x = 0`` that only the odd fine grid samples: rendered there, the shape is slit).
    False when not measured."""
    shift = metrics.get("resolution_shift")
    if shift is None:
        return False
    singular, faces = metrics.get("resolution_singular", 0), metrics.get("faces")
    return (
        shift > cfg.max_resolution_shift
        or metrics["resolution_area"] > cfg.max_resolution_area
        or (faces is not None and singular > cfg.max_resolution_singular * faces)
    )


def judge(
    metrics: Mapping[str, Any],
    cfg: FilterConfig,
    capped: bool,
    one_body: bool = False,
    porous: bool = True,
) -> Verdict:
    """The verdict on :func:`shape_metrics` (or only :func:`quick_metrics`: the checks whose
    metrics are missing are skipped). Every failing reason is listed. ``one_body``: the shape
    was drawn as one connected body (a family with ``one_body``: sculpture, infill, twist),
    so a largest piece under ``min_body_fraction`` of the area is ``fragmented``. ``porous``
    False: the shape was drawn as bodies that do not fall apart (every family but lattice and
    infill), so more than ``max_pieces`` pieces, or a piece under ``min_piece_fraction`` of the
    largest's area (``smallest_piece``), is ``fragmented`` too: a body with flying debris (a
    shape of no family, such as a formula given, is not judged this way)."""
    m = metrics
    reasons: list[str] = []
    if m["faces"] < cfg.min_faces:
        reasons.append("too_small")
    if cfg.require_manifold and (m.get("nonmanifold_edges") or m.get("nonmanifold_vertices")):
        reasons.append("nonmanifold")
    if capped and m.get("watertight") is False:
        reasons.append("not_watertight")
    if (
        m["components"] > cfg.max_components
        or m["largest_component_fraction"] < cfg.min_largest_component_fraction
    ):
        reasons.append("speckle")
    if (one_body and m["largest_component_fraction"] < cfg.min_body_fraction) or (
        not porous
        and (
            m["components"] > cfg.max_pieces
            or m.get("smallest_piece", 1.0) < cfg.min_piece_fraction
        )
    ):
        reasons.append("fragmented")
    if m["box_fraction"] > cfg.max_box_fraction:
        reasons.append("box_dominated")
    if m.get("wall_fraction", 0.0) > cfg.max_wall_fraction:
        reasons.append("walls")
    genus = m.get("genus")
    if genus == 0 and m.get("total_curvature", math.inf) < cfg.blob_max_curvature * m["components"]:
        # Closed genus-0 components have integral |K| >= 4 pi each, with equality exactly when
        # convex: these are lumps, plates or stacks of slabs, capped or not.
        reasons.append("blob")
    if plain(m, cfg):
        reasons.append("plain")
    if unresolved(m, cfg):
        reasons.append("unresolved")
    if genus is not None and genus > cfg.max_genus:
        reasons.append("too_complex")
    return Verdict(not reasons, tuple(reasons))
