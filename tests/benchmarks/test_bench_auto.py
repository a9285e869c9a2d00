"""bench_auto: both paths timed on each shape and grid, what ``auto`` picks there, and what it
loses against the faster."""

from __future__ import annotations

import json

from benchmarks import bench_auto


def test_the_table_says_what_auto_picks_and_what_it_loses(tmp_path, capsys) -> None:
    out = tmp_path / "auto.json"
    bench_auto.main(["--grids", "24,160", "--shapes", "eqA,poles", "--repeats", "1",
                     "--json", str(out)])  # fmt: skip
    rows = json.loads(out.read_text())["results"]["rows"]
    assert [(r["shape"], r["grid"], r["auto"]) for r in rows] == [
        ("eqA", 24, "dense"), ("eqA", 160, "sparse"), ("poles", 24, "dense"),
        ("poles", 160, "sparse"),
    ]  # fmt: skip
    for r in rows:
        picked = r["sparse"] if r["auto"] == "sparse" else r["dense"]
        assert r["loss"] == picked / min(r["dense"], r["sparse"]) >= 1.0
        assert r["ratio"] == r["dense"] / r["sparse"]
        # every one of equation A's 24^3 samples is outside
        assert r["faces"] > 0 or r["grid"] == 24
    # equation A's poles lie between the samples: a few leaves sampled; no leaf of the
    # pole-pierced sphere is pruned
    assert rows[1]["share"] < 0.01 and rows[3]["share"] > 1.0
    text = capsys.readouterr().out
    assert "| eqA | 160 |" in text and "160^3: sparse faster for" in text


def test_a_draw_without_a_surface_is_left_out() -> None:
    assert bench_auto.shape_spec("poles") == (bench_auto.POLES, True)
    assert bench_auto.shapes(None, 2)[:4] == ["eqA", "eqB", "eqC", "poles"]
    assert "sculpture-1" in bench_auto.shapes(None, 2)
