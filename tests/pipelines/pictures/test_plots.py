"""The constituent-function figure: a real PNG, written atomically, with no jump connectors."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
from matplotlib.image import imread

from surfgen.pipelines.pictures.plots import break_jumps, plot_constituents

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def test_plot_constituents_writes_a_png(tmp_path: Path) -> None:
    (tmp_path / "constituents.png").write_bytes(b"an older file is replaced")
    out = plot_constituents(tmp_path / "constituents.png")
    assert out == tmp_path / "constituents.png"
    data = out.read_bytes()
    assert data[:8] == PNG_SIGNATURE
    assert data[12:16] == b"IHDR"
    width, height = struct.unpack(">II", data[16:24])
    assert width > 600 and height > 600
    assert len(data) > 30_000  # five panels of curves, not a blank canvas
    pixels = imread(out)[..., :3]
    assert pixels.std() > 0.05  # not a uniform image
    assert len(np.unique(pixels.reshape(-1, 3), axis=0)) > 50  # several colours drawn
    assert [p.name for p in tmp_path.iterdir()] == ["constituents.png"]  # no temp file left


def test_break_jumps_inserts_nan_only_at_jumps() -> None:
    x = np.linspace(0.0, 2.5, 251)
    y = np.floor(x) + 0.1 * x  # jumps of 1 at x = 1 and 2, slope 0.1 elsewhere
    bx, by = break_jumps(x, y)
    assert np.isnan(by).sum() == 2 and len(bx) == len(x) + 2
    np.testing.assert_array_equal(bx[~np.isnan(bx)], x)
    finite = ~np.isnan(by)
    np.testing.assert_array_equal(by[finite], y)
    gaps = np.flatnonzero(np.isnan(by))
    np.testing.assert_allclose([bx[g - 1] for g in gaps], [0.99, 1.99])
    np.testing.assert_allclose([bx[g + 1] for g in gaps], [1.0, 2.0])
