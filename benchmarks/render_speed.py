"""Benchmark: headless pictures of a ~200k-face marching-cubes gyroid.

Prints seconds per 256² render, per thumbnail PNG, per 12-view turntable strip, and the
speed-up over matplotlib's ``plot_trisurf`` (Agg, no display) drawing the same mesh at the
same size in the same run. Times are the best of ``--repeats`` runs (shared machines are
noisy; ratios are more reliable than absolute figures).

    python -m benchmarks.render_speed [--grid 128] [--box 1.3] [--repeats 5] [--full-baseline]
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from skimage import measure

from benchmarks import harness
from surfgen.generator.mesh.mesh import Mesh
from surfgen.pipelines.pictures.raster import render_image, render_thumbnail, render_turntable


def gyroid_mesh(grid: int, half_periods: float) -> Mesh:
    """Gyroid sheet on ``grid``³ points of the cube ``[-h·π, h·π]³`` (both ends included)."""
    t = np.linspace(-half_periods * np.pi, half_periods * np.pi, grid)
    x, y, z = np.meshgrid(t, t, t, indexing="ij")
    f = np.sin(x) * np.cos(y) + np.sin(y) * np.cos(z) + np.sin(z) * np.cos(x)
    vertices, faces, _, _ = measure.marching_cubes(f, 0.0, spacing=(t[1] - t[0],) * 3)
    return Mesh(vertices + t[0], faces)


def timed(fn: Callable[[], object], repeat: int) -> tuple[float, float]:
    """Best and median wall-clock seconds of ``repeat`` calls."""
    timing = harness.best_of(fn, repeat, warmup=0)
    return timing.best, timing.median


def matplotlib_render(mesh: Mesh, size: int, azimuth: float = 30.0) -> np.ndarray:
    """The baseline: ``plot_trisurf`` at ``size``² pixels with Agg, returned as RGB."""
    import matplotlib  # deferred: optional, and the backend is chosen before pyplot loads

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    dpi = 100
    fig = plt.figure(figsize=(size / dpi, size / dpi), dpi=dpi)
    ax = fig.add_axes((0, 0, 1, 1), projection="3d")
    v = mesh.vertices
    ax.plot_trisurf(v[:, 0], v[:, 1], v[:, 2], triangles=mesh.faces, cmap="viridis", lw=0)
    ax.view_init(elev=25.0, azim=azimuth)
    ax.set_axis_off()
    fig.canvas.draw()
    image = np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
    plt.close(fig)
    return image


def main(argv: list[str] | None = None) -> None:
    parser = harness.parser(__doc__, repeats=5)
    parser.add_argument("--grid", type=int, default=128)
    parser.add_argument("--box", type=float, default=1.3, help="half-width in units of π")
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument(
        "--full-baseline", action="store_true", help="also time 12 matplotlib views"
    )
    args = parser.parse_args(argv)
    run = harness.Run("render_speed", args)

    start = time.perf_counter()
    mesh = gyroid_mesh(args.grid, args.box)
    run.say(
        f"mesh: gyroid {args.grid}³, {mesh.n_faces:,} faces, {mesh.n_vertices:,} vertices "
        f"({time.perf_counter() - start:.2f} s to build)"
    )

    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder)
        start = time.perf_counter()
        render_image(mesh, size=args.size)
        run.say(f"first call (numba cache load or compile): {time.perf_counter() - start:.3f} s")

        image_best, image_med = timed(lambda: render_image(mesh, size=args.size), args.repeats)
        thumb_best, thumb_med = timed(
            lambda: render_thumbnail(mesh, out / "thumb.png", size=args.size), args.repeats
        )
        spin_best, spin_med = timed(
            lambda: render_turntable(mesh, out / "spin.png", views=12, size=args.size),
            max(1, args.repeats // 2),
        )
        base_best, base_med = timed(lambda: matplotlib_render(mesh, args.size), 2)

        run.say(f"render_image {args.size}²      : {image_best:.3f} s (median {image_med:.3f})")
        run.say(f"render_thumbnail (PNG)   : {thumb_best:.3f} s (median {thumb_med:.3f})")
        run.say(f"render_turntable 12 views: {spin_best:.3f} s (median {spin_med:.3f})")
        run.say(f"matplotlib plot_trisurf  : {base_best:.3f} s (median {base_med:.3f})")
        run.say(f"speed-up, thumbnail vs matplotlib: {base_best / thumb_best:.0f}x")
        if args.full_baseline:
            start = time.perf_counter()
            for i in range(12):
                matplotlib_render(mesh, args.size, azimuth=30.0 + 30.0 * i)
            base_spin = time.perf_counter() - start
            run.say(f"matplotlib 12 views      : {base_spin:.3f} s")
            run.say(f"speed-up, turntable vs matplotlib: {base_spin / spin_best:.0f}x")
        else:
            run.say(f"speed-up, turntable vs 12 x matplotlib: {12 * base_best / spin_best:.0f}x")
    run.record(
        faces=mesh.n_faces,
        seconds={
            "render_image": image_best,
            "render_thumbnail": thumb_best,
            "render_turntable": spin_best,
            "matplotlib": base_best,
        },
    )
    run.save()


if __name__ == "__main__":
    main()
