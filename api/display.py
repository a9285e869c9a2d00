"""How the API's objects show themselves: trimesh meshes with their facts, pictures, and the
HTML a notebook displays.

The pictures are the catalogue's (:func:`surfgen.pipelines.pictures.raster.render_image`: a
shaded view of the mesh, the same bits on every machine).
"""

from __future__ import annotations

import base64
import html
import io
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # the mesh and picture modules load numba, trimesh and PIL: when used
    import trimesh
    from PIL import Image  # deferred with the rasteriser: only pictures need PIL

    from surfgen.generator.mesh.mesh import Mesh

THUMBNAIL_SIZE = 256  # pixels: the catalogue's thumbnails


def to_trimesh(mesh: Mesh, metadata: Mapping[str, Any]) -> trimesh.Trimesh:
    """``mesh`` as a :class:`trimesh.Trimesh` with ``metadata``, vertices and faces as they are.

    ``process=False``: trimesh's default merges coincident vertices, which pinches marching
    cubes surfaces (docs: FIELD-NOTES, "Meshes downstream"). Face kinds (``walls="mark"``) are
    the face attribute ``kind`` (0 root, 1 pole, 2 jump, 3 cap).
    """
    import trimesh  # deferred: trimesh (with scipy) is heavy and `import surfgen` stays light

    tm = trimesh.Trimesh(
        np.array(mesh.vertices), np.array(mesh.faces), process=False, metadata=dict(metadata)
    )
    if mesh.face_kinds is not None:
        tm.face_attributes["kind"] = np.array(mesh.face_kinds)
    return tm


def from_trimesh(tm: trimesh.Trimesh) -> Mesh:
    """The surfgen :class:`~surfgen.generator.mesh.mesh.Mesh` of a trimesh mesh (its face
    attribute ``kind`` as the face kinds)."""
    from surfgen.generator.mesh.mesh import Mesh  # deferred: the mesh module loads numba

    kinds = tm.face_attributes.get("kind")
    return Mesh(tm.vertices, tm.faces, None if kinds is None else np.asarray(kinds))


def picture(mesh: Mesh, size: int = THUMBNAIL_SIZE) -> Image.Image:
    """The catalogue's shaded view of ``mesh`` as a PIL image (RGB, ``size`` × ``size``)."""
    from PIL import Image  # deferred with the rasteriser: only pictures need PIL

    # deferred: the rasteriser's kernels are numba's
    from surfgen.pipelines.pictures.raster import render_image

    return Image.fromarray(render_image(mesh, size=size))


def png_of(image: Image.Image) -> bytes:
    """The PNG file of ``image``, in memory."""
    buffer = io.BytesIO()
    image.save(buffer, format="PNG")
    return buffer.getvalue()


def facts_html(
    title: str, facts: Sequence[tuple[str, Any]], png: bytes | None = None, note: str = ""
) -> str:
    """A notebook card: the picture (if any) beside a table of ``facts``."""
    rows = "".join(
        f"<tr><th style='text-align:left;padding-right:1em'>{html.escape(str(k))}</th>"
        f"<td style='text-align:left'>{_cell(v)}</td></tr>"
        for k, v in facts
    )
    image = ""
    if png is not None:
        data = base64.b64encode(png).decode("ascii")
        image = (
            f"<img src='data:image/png;base64,{data}' width='{THUMBNAIL_SIZE}' "
            f"height='{THUMBNAIL_SIZE}' alt='{html.escape(title)}' style='margin-right:1em'>"
        )
    caption = f"<p>{html.escape(note)}</p>" if note else ""
    return (
        f"<div class='surfgen'><strong>{html.escape(title)}</strong>"
        f"<div style='display:flex;align-items:flex-start'>{image}<table>{rows}</table></div>"
        f"{caption}</div>"
    )


def _cell(value: Any) -> str:
    if isinstance(value, str):
        return f"<code>{html.escape(value)}</code>" if len(value) > 24 else html.escape(value)
    if isinstance(value, float):
        return html.escape(f"{value:.6g}")
    return html.escape(str(value))


def shorten(text: str, limit: int = 60) -> str:
    """``text`` cut to ``limit`` characters (``...`` when cut), for a one-line repr."""
    return text if len(text) <= limit else text[: limit - 3] + "..."
