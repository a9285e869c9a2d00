"""surfgen: 3D surfaces from random implicit functions, as a Python library.

A shape is a :class:`Surface` (a formula, its box and grid): make one from a formula, a preset
or a MathMod script, or :func:`draw` it from the sampler; ask it for its field (a numpy array),
its mesh (a :class:`trimesh.Trimesh`), its metrics and the filters' verdict. :func:`sample`
fills a :class:`Catalogue` as ``surfgen sample`` does; :func:`shapes` streams the same accepted
shapes without files. Errors are :class:`SurfgenError` subclasses, with the messages the
command line prints.

Importing surfgen loads no numba, trimesh or pymeshlab: the functions that compute import them.
The layers beneath (``surfgen.generator``, ``surfgen.filters``, ``surfgen.pipelines``) are the
implementation; this package is the public surface.
"""

from surfgen.catalogue import Catalogue, Record
from surfgen.generator import __version__
from surfgen.generator.errors import (
    EmptySurface,
    FormulaError,
    FormulaSyntaxError,
    GridError,
    MeshError,
    SpecError,
    SurfgenError,
)
from surfgen.generator.formula.limits import LimitError
from surfgen.generator.model.presets import PRESETS as _PRESETS
from surfgen.pipelines.catalogue.store import CatalogueError
from surfgen.sampling import Shape, draw, sample, shapes
from surfgen.surface import Check, Surface

__all__ = [
    "Catalogue",
    "CatalogueError",
    "Check",
    "EmptySurface",
    "FormulaError",
    "FormulaSyntaxError",
    "GridError",
    "LimitError",
    "MeshError",
    "Record",
    "Shape",
    "SpecError",
    "Surface",
    "SurfgenError",
    "__version__",
    "draw",
    "presets",
    "sample",
    "shapes",
]


def presets() -> list[str]:
    """The names of the presets :meth:`Surface.from_preset` takes (``surfgen presets``)."""
    return list(_PRESETS)
