"""The pictures of many shapes on every core: thumbnails and turntables drawn in worker processes.

``surfgen thumbnails`` and ``surfgen gallery -o`` draw what a catalogue is missing; for the main
job's 1000 shapes that is 1000 turntables of 12 views, about four minutes on one core. Here the
drawing (read the mesh, render, encode the PNG) runs in a :class:`~surfgen.pipelines.run.executor.
KillablePool` and the bytes come back to the parent, which alone writes the catalogue (its files
and rows as one transaction, :mod:`surfgen.pipelines.pictures.thumbnails`). The pictures are the same bytes
whichever process draws them.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

from surfgen.generator.errors import SurfgenError
from surfgen.pipelines.run.executor import KillablePool

log = logging.getLogger(__name__)

KINDS = ("thumb", "turntable")
TIMEOUT = 600.0  # seconds per shape: a picture of a huge mesh takes seconds, not minutes


@dataclass(frozen=True)
class Job:
    """The pictures (``kinds``: a subset of :data:`KINDS`) of the shape ``key`` whose mesh
    is the file ``mesh``."""

    key: str
    mesh: str
    kinds: tuple[str, ...]


@dataclass(frozen=True)
class Drawn:
    """A job's PNG files by kind, or why there are none (``error``)."""

    job: Job
    pictures: dict[str, bytes]
    error: str | None = None


def draw(job: Job) -> Drawn:
    """Read the mesh and draw the job's pictures, in memory. A mesh that cannot be read or
    drawn gives its :class:`SurfgenError` message as ``error``."""
    from surfgen.generator.mesh.exchange import load_mesh
    from surfgen.pipelines.pictures.raster import (
        THUMBNAIL_SIZE,
        TURNTABLE_SIZE,
        TURNTABLE_VIEWS,
        png_bytes,
        render_image,
        turntable_image,
    )

    try:
        mesh = load_mesh(job.mesh)
        pictures = {}
        if "thumb" in job.kinds:
            pictures["thumb"] = png_bytes(render_image(mesh, size=THUMBNAIL_SIZE))
        if "turntable" in job.kinds:
            image = turntable_image(mesh, views=TURNTABLE_VIEWS, size=TURNTABLE_SIZE)
            pictures["turntable"] = png_bytes(image)
    except SurfgenError as exc:
        return Drawn(job, {}, str(exc))
    return Drawn(job, pictures)


def default_workers() -> int:
    return os.cpu_count() or 1


def draw_all(
    jobs: Sequence[Job],
    workers: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> Iterator[Drawn]:
    """Every job drawn, in completion order, on ``workers`` processes (default: one per core).

    The first job is drawn here, before the workers are forked: it loads (or, on a fresh
    machine, compiles) the renderer's kernels, which the workers then inherit. With one worker,
    or one job, nothing is forked. A worker that dies or overruns :data:`TIMEOUT` costs only
    its job, reported as an ``error``. ``progress(done, total)`` after each job."""

    workers = default_workers() if workers is None else workers
    total = len(jobs)
    for done, job in enumerate(jobs[:1] if workers > 1 else jobs, start=1):
        yield draw(job)
        if progress is not None:
            progress(done, total)
    if workers <= 1 or total <= 1:
        return
    done = 1
    with KillablePool(draw, min(workers, total - 1), TIMEOUT) as pool:
        for result in pool.run(jobs[1:]):
            if result.status == "ok":
                yield result.value
            else:
                # the caller reports the failures as a whole (render_pictures: a count)
                log.info("shape %s: no pictures (%s)", result.task.key, result.message)
                yield Drawn(result.task, {}, result.message)
            done += 1
            if progress is not None:
                progress(done, total)
