"""What a mesh is like, in numbers: :class:`Metrics` and :func:`measure_mesh`.

Edges, Euler characteristic, orientation, area, volume and bbox are counted with numba kernels
(:mod:`surfgen.filters.geometry`: one pass each, the same numbers as the numpy expressions they
replaced). Components and non-manifold vertices are pymeshlab's measures: counted by the
same edge pass wherever they are provably pymeshlab's numbers (no edge with more than two
faces, no face repeating a vertex: every mesh the sampler accepts), asked of pymeshlab through
:mod:`surfgen.filters.meshlab` elsewhere. pymeshlab's measures took a seventh of the main job's
CPU (copying the mesh in, then nine measures of which these two were read), the edge pass a
few percent of that.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from surfgen.filters import meshlab
from surfgen.filters.geometry import column_bounds, edge_counts, used_mask, volume_terms
from surfgen.generator.errors import MeshError
from surfgen.generator.mesh.mesh import Mesh, face_areas


@dataclass(frozen=True, slots=True)
class Metrics:
    """Measures of one mesh.

    ``euler`` is V - E + F over referenced vertices.  ``watertight``: every edge has exactly two
    faces.  The mesh is *closed* when it is watertight, has no non-manifold vertex and its faces
    are consistently oriented; only then are ``genus`` (total over components, from
    ``euler = 2*components - 2*genus``) and ``volume`` (signed: positive when normals point
    outward) given, else they are None.  ``nonmanifold_edges`` counts distinct edges with more
    than two faces.  ``bbox`` is ``(xmin, xmax, ymin, ymax, zmin, zmax)``.
    """

    vertices: int
    faces: int
    components: int
    euler: int
    genus: int | None
    watertight: bool
    boundary_edges: int
    nonmanifold_edges: int
    nonmanifold_vertices: int
    area: float
    volume: float | None
    bbox: tuple[float, float, float, float, float, float]

    @property
    def closed(self) -> bool:
        return self.genus is not None

    def to_dict(self) -> dict[str, Any]:
        """Plain, JSON-ready Python values under exactly the field names."""
        d = asdict(self)
        d["bbox"] = [float(v) for v in self.bbox]
        return d


def measure_mesh(mesh: Mesh) -> Metrics:
    """Measure ``mesh`` (``(V, 3)`` vertices, ``(F, 3)`` faces).

    Raises :class:`MeshError` for a mesh without faces.
    """
    if mesh.n_faces == 0:
        raise MeshError("cannot measure an empty mesh (no faces)")
    v, f = mesh.vertices, mesh.faces
    # The cheap numpy/numba counts first: pymeshlab's topology is the slow part.
    edges = _edge_counts(f, mesh.n_vertices)
    used = used_mask(f, mesh.n_vertices)
    euler = int(np.count_nonzero(used)) - edges.count + mesh.n_faces
    if edges.nonmanifold or edges.degenerate:  # the edge pass's numbers are not pymeshlab's
        topo = meshlab.topology(mesh)
        components = int(topo["components"])  # type: ignore[arg-type]
        nonmanifold_vertices = int(topo["nonmanifold_vertices"])  # type: ignore[arg-type]
    else:
        components, nonmanifold_vertices = edges.components, edges.pinched
    watertight = edges.boundary == 0 and edges.nonmanifold == 0
    closed = watertight and nonmanifold_vertices == 0 and edges.oriented

    # Per-face terms from one-pass kernels, summed by numpy as before (module geometry).
    area = float(face_areas(mesh).sum())
    genus = volume = None
    if closed:
        # chi = 2c - 2g holds for closed orientable surfaces; chi is even there.
        genus = (2 * components - euler) // 2
        # Divergence theorem about the bbox centre, which keeps the sum well conditioned.
        v_lo, v_hi = column_bounds(v, np.ones(len(v), dtype=np.bool_))
        o = 0.5 * (v_lo + v_hi)
        volume = float(volume_terms(v, f, o).sum() / 6.0)
    lo, hi = column_bounds(v, used)
    return Metrics(
        vertices=mesh.n_vertices,
        faces=mesh.n_faces,
        components=components,
        euler=int(euler),
        genus=None if genus is None else int(genus),
        watertight=bool(watertight),
        boundary_edges=edges.boundary,
        nonmanifold_edges=edges.nonmanifold,
        nonmanifold_vertices=nonmanifold_vertices,
        area=area,
        volume=volume,
        bbox=tuple(float(x) for pair in zip(lo, hi, strict=True) for x in pair),  # type: ignore[arg-type]
    )


@dataclass(frozen=True, slots=True)
class _Edges:
    count: int  # distinct undirected edges
    boundary: int  # edges with one face
    nonmanifold: int  # edges with more than two faces
    oriented: bool  # every two-face edge is walked once in each direction
    degenerate: bool  # a face repeats a vertex
    components: int  # faces joined through shared edges
    pinched: int  # vertices whose faces make more than one fan


def _edge_counts(faces: np.ndarray, n_vertices: int) -> _Edges:
    """Count edges from the ``3F`` half-edges (one pass, see :func:`geometry.edge_counts`)."""
    count, boundary, nonmanifold, oriented, degenerate, components, pinched = edge_counts(
        faces, n_vertices
    )
    return _Edges(
        count=int(count),
        boundary=int(boundary),
        nonmanifold=int(nonmanifold),
        oriented=bool(oriented),
        degenerate=bool(degenerate),
        components=int(components),
        pinched=int(pinched),
    )
