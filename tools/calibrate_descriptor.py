"""Calibrate the near-duplicate descriptor's channel scales on a catalogue.

Each accepted shape's catalogue mesh is compared with the same formula meshed on a grid of
3/4 the size (another sampling of the surface): the same shape, slightly changed. A channel's
scale is a percentile (default 95) of those same-shape distances. Then, with the scales in
:data:`surfgen.filters.descriptor.CHANNEL_SCALES`, it prints the near-duplicate rate of the
catalogue (overall and per family) and writes a picture of its closest pairs to look at.

    python -m tools.calibrate_descriptor out/catalogue --pairs out/closest-pairs.png
"""

from __future__ import annotations

import argparse
import json
import sqlite3
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from surfgen.filters.descriptor import (
    CHANNEL_SCALES,
    DEFAULT_THRESHOLD,
    channel_distances,
    descriptor,
    descriptor_distances,
)
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.mesh.exchange import load_mesh
from surfgen.generator.mesh.mesh import extract_mesh
from surfgen.generator.model.spec import SurfaceSpec


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("catalogue", type=Path)
    ap.add_argument("--percentile", type=float, default=95.0)
    ap.add_argument("--limit", type=int, default=None, help="only the first N accepted shapes")
    ap.add_argument("--pairs", type=Path, default=None, help="PNG of the 24 closest pairs")
    args = ap.parse_args()

    con = sqlite3.connect(args.catalogue / "catalogue.sqlite")
    con.row_factory = sqlite3.Row
    rows = list(
        con.execute(
            "SELECT key, spec, mesh_path, thumb_path, model FROM shapes "
            "WHERE verdict='accepted' ORDER BY run, idx"
        )
    )[: args.limit]
    own, coarse, families = [], [], []
    for r in rows:
        own.append(descriptor(load_mesh(args.catalogue / r["mesh_path"])))
        spec = SurfaceSpec.from_json(r["spec"])
        spec = spec.replace(grid=tuple(max(8, g * 3 // 4) for g in spec.grid))
        field = evaluate(spec.tree(), spec.to_grid(), spec.params)
        coarse.append(descriptor(extract_mesh(field, spec.level, cap=True)))
        families.append(json.loads(r["model"] or "{}").get("family", "?"))
    own_a, coarse_a = np.stack(own), np.stack(coarse)
    same = {k: [] for k in CHANNEL_SCALES}
    for i in range(len(rows)):
        for k, v in channel_distances(own_a[i], coarse_a[i : i + 1]).items():
            same[k].append(float(v[0]))
    print(f"{len(rows)} shapes; same shape (grid x 3/4), per channel:")
    for k, v in same.items():
        pct = np.percentile(v, [50, 90, args.percentile])
        print(
            f"  {k:10s} median {pct[0]:.4f}  p90 {pct[1]:.4f}  p{args.percentile:g} {pct[2]:.4f}"
            f"  (scale in use {CHANNEL_SCALES[k]})"
        )
    same_total = np.array(
        [descriptor_distances(own_a[i], coarse_a[i : i + 1])[0] for i in range(len(rows))]
    )
    print(
        f"same shape recognised (distance < {DEFAULT_THRESHOLD:g}): "
        f"{np.mean(same_total < DEFAULT_THRESHOLD):.1%}"
    )
    nearest, partner = [], []
    for i in range(len(rows)):
        d = descriptor_distances(own_a[i], own_a)
        d[i] = np.inf
        nearest.append(float(d.min()))
        partner.append(int(d.argmin()))
    nearest_a, fam = np.array(nearest), np.array(families)
    print(
        f"near-duplicate rate: {np.mean(nearest_a < DEFAULT_THRESHOLD):.1%}, median nearest "
        f"distance {np.median(nearest_a):.2f}"
    )
    for f in sorted(set(families)):
        m = fam == f
        print(f"  {f:10s} {m.sum():5d} shapes, near duplicates {np.mean(nearest_a[m] < 1):.1%}")
    if args.pairs:
        _pairs_sheet(args, rows, nearest_a, partner)


def _pairs_sheet(args, rows, nearest, partner) -> None:
    seen, pairs = set(), []
    for i in np.argsort(nearest):
        pair = frozenset((int(i), partner[i]))
        if pair not in seen:
            seen.add(pair)
            pairs.append((int(i), partner[i], nearest[i]))
    size = 128
    sheet = Image.new("RGB", (size * 8, (size + 14) * 6), "white")
    draw = ImageDraw.Draw(sheet)
    for n, (i, j, d) in enumerate(pairs[:24]):
        x, y = (n % 4) * 2 * size, (n // 4) * (size + 14)
        for side, k in enumerate((i, j)):
            thumb = rows[k]["thumb_path"]
            if thumb and (args.catalogue / thumb).exists():
                im = Image.open(args.catalogue / thumb).convert("RGB").resize((size, size))
                sheet.paste(im, (x + side * size, y))
        draw.text((x + size - 24, y + size), f"{d:.2f}", fill="black")
    sheet.save(args.pairs)
    print(f"closest pairs: {args.pairs}")


if __name__ == "__main__":
    main()
