"""Mesh file formats: one table of what each can do (:data:`FORMATS`).

A new format is one :class:`Format` entry (its reader is trimesh's, chosen by
``trimesh_type``, and so is its writer unless :mod:`surfgen.generator.mesh.exchange` has its
own in ``OWN_WRITERS``: binary PLY): every list of formats (the
suffixes ``save_mesh`` accepts, ``export --format``, ``dataset --format``, the help texts and
messages naming them) is read from the table.  Plain data: the CLI reads it without loading
the mesh modules.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Format:
    """One mesh format and what it can do.

    ``trimesh_type``/``options``: how trimesh reads (and, but for PLY, writes) it; ``binary``:
    a binary file;
    ``printable``: meant for printing (must hold a closed solid; ``export`` writes it in
    millimetres); ``marks_walls``: carries the face kinds of ``--walls mark`` (and their
    colours); ``mesh_file``: ``save_mesh`` writes it and ``load_mesh`` reads it;
    ``export_order``: its place in ``surfgen export --format``'s list (None: not exported);
    ``dataset``: ``surfgen dataset`` can ship it; ``needs``: an optional module it needs.
    """

    name: str
    trimesh_type: str
    binary: bool
    printable: bool = False
    marks_walls: bool = False
    mesh_file: bool = True
    export_order: int | None = None
    dataset: bool = False
    needs: str | None = None
    options: tuple[tuple[str, Any], ...] = ()

    @property
    def suffix(self) -> str:
        return f".{self.name}"


# In the order the suffixes are listed (save_mesh's message, render's help): STL and PLY
# binary keep files small and exact.
FORMATS: dict[str, Format] = {
    f.name: f
    for f in (
        Format("ply", "ply", True, marks_walls=True, export_order=2, dataset=True),
        Format("obj", "obj", False, export_order=1,
               options=(("include_normals", False), ("include_texture", False))),
        Format("stl", "stl", True, printable=True, export_order=0),
        Format("off", "off", False),
        Format("glb", "glb", True, marks_walls=True, export_order=3, dataset=True),
        Format("3mf", "3mf", True, printable=True, mesh_file=False, export_order=4,
               needs="lxml"),
    )
}  # fmt: skip
MESH_SUFFIXES = tuple(f.suffix for f in FORMATS.values() if f.mesh_file)
EXPORT_FORMATS = tuple(
    f.name
    for f in sorted(FORMATS.values(), key=lambda f: f.export_order or 0)
    if f.export_order is not None
)
MARKABLE = tuple(f.name for f in FORMATS.values() if f.marks_walls)
PRINTABLE = tuple(f.name for f in FORMATS.values() if f.printable and f.export_order is not None)
DATASET_FORMATS = tuple(f.name for f in FORMATS.values() if f.dataset)
