"""A catalogue folder as a Python value: :class:`Catalogue` (iterate, query, curate, export)
and its :class:`Record` objects (one shape each: its facts, surface, mesh and thumbnail).

Each operation opens the catalogue's database for itself, read-only unless it writes (as the
``surfgen catalogue`` commands do), so a :class:`Catalogue` holds no connection and a
``surfgen sample`` or ``serve`` can run beside it.
"""

from __future__ import annotations

import html
import json
import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from surfgen.display import (
    THUMBNAIL_SIZE,
    facts_html,
    from_trimesh,
    picture,
    png_of,
    shorten,
    to_trimesh,
)
from surfgen.generator.errors import SpecError, SurfgenError
from surfgen.generator.model.sampler import SAMPLER_VERSION, draw_equation
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.catalogue.curation import apply_action, get_shape, select_shapes
from surfgen.pipelines.catalogue.store import CatalogueError, open_catalogue
from surfgen.pipelines.run.config import config_from_dict
from surfgen.settings import mesh_walls
from surfgen.surface import Surface

if TYPE_CHECKING:
    import trimesh
    from PIL import Image

    from surfgen.pipelines.run.sampling import RunSummary

SHOWN = 12  # thumbnails a catalogue shows in a notebook


class Catalogue:
    """The catalogue in a folder (``surfgen sample --out``).

    ``len`` and iteration cover the shapes the filters accepted, by run and index;
    ``catalogue[key]`` finds any shape by its key or a unique key prefix.

    Parameters
    ----------
    path : path
        The catalogue folder (it holds ``catalogue.sqlite``).

    Raises
    ------
    CatalogueError
        No catalogue there, or a damaged or foreign database.
    """

    def __init__(
        self, path: str | os.PathLike[str] = "out/catalogue", *, summary: RunSummary | None = None
    ) -> None:
        self.path = Path(path)
        self.summary = summary
        """The run :func:`surfgen.sample` just made (None when opened by path)."""
        with open_catalogue(self.path, readonly=True):
            pass  # one line naming the problem now, not at first use

    # -- reading -------------------------------------------------------------------------------

    def __len__(self) -> int:
        with open_catalogue(self.path, readonly=True) as cat:
            row = cat.conn.execute("SELECT COUNT(*) FROM shapes WHERE verdict = 'accepted'")
            return int(row.fetchone()[0])

    def __iter__(self) -> Iterator[Record]:
        return iter(self.query())

    def __getitem__(self, key: str) -> Record:
        """The shape with this key or unique key prefix, with its run and curation history.

        Raises
        ------
        CatalogueError
            No such key, or an ambiguous prefix.
        """
        with open_catalogue(self.path, readonly=True) as cat:
            return Record(self.path, get_shape(cat, key))

    def __contains__(self, key: object) -> bool:
        if not isinstance(key, str):
            return False
        try:
            self[key]
        except CatalogueError:
            return False
        return True

    def query(
        self,
        where: str | None = None,
        sort: str | None = None,
        *,
        limit: int | None = None,
        everything: bool = False,
    ) -> list[Record]:
        """The shapes matching ``where``, ordered by ``sort``: ``surfgen catalogue list``.

        Parameters
        ----------
        where : str, optional
            A condition such as ``"genus >= 2 and components < 5 and not rejected"``
            (fields and operators: ``docs/guide/curation.md``).
        sort : str, optional
            ``FIELD`` or ``-FIELD`` (descending), comma-separated; ties by run and index.
        limit : int, optional
            At most this many.
        everything : bool
            Include the draws the filters rejected (also when ``where`` names ``verdict``
            or ``reason``).

        Raises
        ------
        WhereError
            An expression that does not parse or names an unknown field (the column named).
        """
        with open_catalogue(self.path, readonly=True) as cat:
            rows = select_shapes(cat, where=where, sort=sort, limit=limit, everything=everything)
        return [Record(self.path, r) for r in rows]

    def runs(self) -> list[dict[str, Any]]:
        """The catalogue's runs (seed, grid, n, accepted, status, config...), oldest first."""
        with open_catalogue(self.path, readonly=True) as cat:
            return cat.runs()

    # -- curating ------------------------------------------------------------------------------

    def star(self, key: str, stars: int = 1) -> Record:
        """Give a shape 0 to 5 stars (0 removes them); returns its new record."""
        return self._act(key, "star", stars)

    def tag(self, key: str, *tags: str) -> Record:
        """Add tags (1-40 characters a-z 0-9 _ . -)."""
        return self._act(key, "tag", list(tags))

    def untag(self, key: str, *tags: str) -> Record:
        """Remove tags."""
        return self._act(key, "untag", list(tags))

    def reject(self, key: str, why: str) -> Record:
        """Reject a shape by hand (it stays, hidden from the gallery); ``why`` is required."""
        return self._act(key, "reject", why)

    def unreject(self, key: str) -> Record:
        """Undo a curator's rejection."""
        return self._act(key, "unreject")

    def note(self, key: str, text: str) -> Record:
        """Write a note on a shape (``''`` removes it)."""
        return self._act(key, "note", text)

    def _act(self, key: str, action: str, value: Any = None) -> Record:
        """One curation action, committed at once (``surfgen catalogue star|tag|...``).

        Raises ``CatalogueError`` for an unknown key and ``CurationError`` for a bad value.
        """
        with open_catalogue(self.path, must_exist=True) as cat:
            return Record(self.path, apply_action(cat, key, action, value))

    # -- exporting -----------------------------------------------------------------------------

    def export(
        self,
        keys: str | Sequence[str],
        out: str | os.PathLike[str],
        *,
        format: str = "stl",
        size: float | None = None,
        regrid: int | None = None,
        walls: str = "keep",
        remesh: bool = False,
        target_edge: float | None = None,
        target_faces: int | None = None,
        smooth: int = 0,
        min_component: float = 1e-3,
        force: bool = False,
    ) -> list[Path]:
        """Clean up shapes and write print- or render-ready files: ``surfgen export``.

        Each shape gives ``<key>.<format>`` and a sidecar ``<key>.json`` in ``out``; nothing
        is written unless every one succeeds. ``size`` scales the longest bbox side to that
        many millimetres; ``regrid`` re-evaluates on ``regrid``³ points; the other options are
        ``surfgen export``'s.

        Returns
        -------
        list of Path
            The mesh files written, in the order of ``keys``.

        Raises
        ------
        ExportError
            A bad option, or a printable format (STL, 3MF) for a mesh that is not watertight
            and manifold (unless ``force``).
        """
        # deferred: cleanup and the writers load pymeshlab and trimesh
        from surfgen.filters.cleanup import CleanupOptions
        from surfgen.pipelines.export.meshes import ExportOptions, export_shapes

        cleanup = CleanupOptions(
            min_component=min_component,
            remesh=remesh,
            target_edge=target_edge,
            target_faces=target_faces,
            smooth=smooth,
        )
        options = ExportOptions(
            format=format, cleanup=cleanup, size=size, regrid=regrid, force=force, walls=walls
        )
        inputs = [keys] if isinstance(keys, str) else list(keys)
        results = export_shapes(inputs, Path(out), options, self.path)
        return [r.file for r in results]

    # -- showing -------------------------------------------------------------------------------

    def __repr__(self) -> str:
        return f"Catalogue({str(self.path)!r}: {len(self)} accepted shapes)"

    def _repr_html_(self) -> str:
        shown = self.query(limit=SHOWN)
        cells = "".join(r._figure() for r in shown)
        more = len(self) - len(shown)
        tail = f"<p>… and {more} more</p>" if more > 0 else ""
        return (
            f"<div class='surfgen'><strong>{html.escape(repr(self))}</strong>"
            f"<div style='display:flex;flex-wrap:wrap'>{cells}</div>{tail}</div>"
        )


@dataclass(frozen=True, eq=False)
class Record:
    """One catalogued shape, as ``surfgen catalogue show --json`` (or ``list --json``) gives
    it: :meth:`to_dict` is that JSON object.

    Attributes
    ----------
    path : Path
        Its catalogue's folder.
    """

    path: Path
    _data: dict[str, Any]

    @property
    def key(self) -> str:
        """The shape's key."""
        return str(self._data["key"])

    @property
    def formula(self) -> str:
        """The canonical formula (K3DSurf/MathMod syntax)."""
        return str(self._data["formula"])

    @property
    def spec(self) -> SurfaceSpec:
        """Its spec."""
        return SurfaceSpec.from_dict(self._data["spec"])

    @property
    def metrics(self) -> dict[str, Any]:
        """The metrics the run measured (10 significant digits)."""
        return dict(self._data["metrics"])

    @property
    def accepted(self) -> bool:
        """Whether the filters accepted it."""
        return bool(self._data["verdict"] == "accepted")

    @property
    def reasons(self) -> list[str]:
        """The filters' reasons for rejecting it (empty when accepted)."""
        return list(self._data["reasons"])

    @property
    def stars(self) -> int:
        """Stars given by curators (0-5)."""
        return int(self._data["stars"])

    @property
    def tags(self) -> list[str]:
        """Its tags, sorted."""
        return list(self._data["tags"])

    @property
    def note(self) -> str | None:
        """A curator's note."""
        note = self._data["note"]
        return None if note is None else str(note)

    @property
    def rejected(self) -> str | None:
        """Why a curator rejected it (None when not)."""
        why = self._data["rejected"]
        return None if why is None else str(why)

    @property
    def family(self) -> str:
        """The sampler family it was drawn from."""
        return str(self._data["family"])

    def to_dict(self) -> dict[str, Any]:
        """The JSON-ready record (``surfgen catalogue show --json`` for ``catalogue[key]``,
        ``list --json`` items for :meth:`Catalogue.query`)."""
        return dict(self._data)

    @property
    def surface(self) -> Surface:
        """Its surface, meshed as its run meshed it (cap, walls) and judged with its run's
        config (:meth:`Surface.check` then gives the run's verdict and metrics; a sculpture is
        measured against its envelope when this surfgen's sampler drew it)."""
        with open_catalogue(self.path, readonly=True) as cat:
            run = cat.conn.execute(
                "SELECT config FROM runs WHERE id = ?", (self._data["run"],)
            ).fetchone()
        spec = self.spec
        stored = json.loads(run["config"]) if run is not None else {}
        try:
            config = config_from_dict(stored)
        except (SpecError, KeyError, TypeError, AttributeError):
            # a config this surfgen cannot read (another version's) or none: meshed as
            # `catalogue check --repair` re-makes meshes, capped as the run was
            run_table = stored.get("run") if isinstance(stored, dict) else None
            cap = run_table.get("cap", True) if isinstance(run_table, dict) else True
            return Surface(spec, cap=bool(cap))
        prov = spec.provenance
        made = None
        if prov.get("sampler") == SAMPLER_VERSION and prov.get("config") == config.hash:
            # this sampler draws it again: a sculpture's envelope, for Surface.check
            made = draw_equation(int(prov["seed"]), int(prov["index"]), config.sampler)
        walls = mesh_walls(config)
        d = self._data["d"]
        return Surface(spec, cap=config.run.cap, walls=walls, config=config, _draw=made, _d=d)

    def mesh(self) -> trimesh.Trimesh:
        """The catalogued mesh (its PLY file), with ``key`` and ``formula`` in its metadata.

        Raises
        ------
        CatalogueError
            A shape without a mesh (rejected by the filters, or a missing file:
            ``surfgen catalogue check --repair`` re-makes it).
        """
        from surfgen.generator.mesh.exchange import load_mesh  # deferred: trimesh

        mesh_path = self._data["mesh"]
        if not mesh_path or not (self.path / mesh_path).is_file():
            why = "it has no mesh file" if not mesh_path else f"{mesh_path} is missing"
            raise CatalogueError(
                f"shape {self.key}: {why} (surfgen catalogue check --repair re-makes the "
                "meshes of accepted shapes)"
            )
        metadata = {"key": self.key, "formula": self.formula, "spec": self._data["spec"]}
        return to_trimesh(load_mesh(self.path / mesh_path), metadata)

    def thumbnail(self) -> Image.Image:
        """The catalogue's thumbnail (rendered from the mesh when the run made none).

        Returns
        -------
        PIL.Image.Image
            RGB, 256 × 256.
        """
        from PIL import Image  # deferred: only pictures need PIL

        thumb = self._data["thumb"]
        if thumb and (self.path / thumb).is_file():
            with Image.open(self.path / thumb) as image:
                return image.convert("RGB")
        return picture(from_trimesh(self.mesh()), THUMBNAIL_SIZE)

    def __repr__(self) -> str:
        extra = f", stars={self.stars}" if self.stars else ""
        extra += f", tags={self.tags}" if self.tags else ""
        return (
            f"Record(key={self.key!r}, family={self.family!r}, genus={self._data['genus']}, "
            f"faces={self._data['faces']}, formula={shorten(self.formula)!r}{extra})"
        )

    def _png(self) -> bytes | None:
        try:
            return png_of(self.thumbnail())
        except SurfgenError:
            return None

    def _repr_png_(self) -> bytes | None:
        """The thumbnail, for notebooks."""
        return self._png()

    def _repr_html_(self) -> str:
        """A card for notebooks: the thumbnail and the key facts."""
        facts: list[tuple[str, Any]] = [("formula", self.formula), ("family", self.family)]
        facts += [(k, self._data[k]) for k in ("genus", "components", "faces", "area", "volume")]
        facts += [("verdict", self._data["verdict"]), ("stars", self.stars)]
        facts += [("tags", " ".join(self.tags) or "-")]
        return facts_html(f"Record {self.key}", facts, self._png())

    def _figure(self) -> str:
        """A small figure for the catalogue's card: thumbnail and key."""
        return facts_html(self.key, [("genus", self._data["genus"])], self._png())
