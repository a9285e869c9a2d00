"""surfgen: 3D surfaces from random implicit functions, as a Python library.

A shape is a :class:`Surface` (a formula, its box and grid): make one from a formula, a preset
or a MathMod script, or :func:`draw` it from the sampler; ask it for its field (a numpy array),
its mesh (a :class:`trimesh.Trimesh`), its metrics and the filters' verdict. :func:`sample`
fills a :class:`Catalogue` as ``surfgen sample`` does; :func:`shapes` streams the same accepted
shapes without files. Errors are :class:`SurfgenError` subclasses, with the messages the
command line prints.

The layers beneath (``surfgen.generator``, ``surfgen.filters``, ``surfgen.pipelines``) are the
implementation; this package is the public surface. Its names load on first use (PEP 562, as
scikit-image's do): ``import surfgen``, which every ``import surfgen.generator...`` runs first,
costs nothing, and no name loads numba, trimesh or pymeshlab until a function computes.
"""

import importlib as _importlib
import typing as _typing

from surfgen.generator import __version__

if _typing.TYPE_CHECKING:  # what type checkers and the API reference read; loaded by __getattr__
    from surfgen.catalogue import Catalogue, Record
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

# Where each public name lives.
_ERRORS = "surfgen.generator.errors"
_HOMES = {
    "Catalogue": "surfgen.catalogue",
    "Record": "surfgen.catalogue",
    "CatalogueError": "surfgen.pipelines.catalogue.store",
    "LimitError": "surfgen.generator.formula.limits",
    "Shape": "surfgen.sampling",
    "draw": "surfgen.sampling",
    "sample": "surfgen.sampling",
    "shapes": "surfgen.sampling",
    "Check": "surfgen.surface",
    "Surface": "surfgen.surface",
} | {
    name: _ERRORS
    for name in (
        "EmptySurface",
        "FormulaError",
        "FormulaSyntaxError",
        "GridError",
        "MeshError",
        "SpecError",
        "SurfgenError",
    )
}


def __getattr__(name: str) -> _typing.Any:
    """A public name, imported from its module the first time it is asked for."""
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'surfgen' has no attribute {name!r}")
    value = getattr(_importlib.import_module(home), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


def presets() -> list[str]:
    """The names of the presets :meth:`Surface.from_preset` takes (``surfgen presets``)."""
    # here, not at the top: `import surfgen` runs first in every import of its layers
    from surfgen.generator.model.presets import PRESETS

    return list(PRESETS)
