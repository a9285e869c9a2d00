"""Tests for surfgen.pipelines.studies.report: the statistics and the self-contained HTML report."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from surfgen.filters.descriptor import (
    D1_BINS,
    D2_BINS,
    NORMAL_BINS,
    SIZE,
    descriptor_from_text,
    descriptor_to_text,
)
from surfgen.filters.diversity import BANDWIDTH, descriptor_vendi
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.catalogue.curation import apply_action
from surfgen.pipelines.catalogue.store import CatalogueError, open_catalogue
from surfgen.pipelines.cli.main import main
from surfgen.pipelines.studies.report import render_report, report_stats

# (run, genus, components, faces) of accepted shapes; rejected draws: (run, reasons)
ACCEPTED = [(1, 0, 1, 900), (1, 1, 1, 2500), (1, 1, 3, 4000), (1, 3, 2, 12000), (2, 7, 1, 50000)]
REJECTED = [(1, ["noise"]), (1, ["noise", "speckle"]), (1, ["duplicate"]), (2, ["empty"])]


def _descriptor(shift: int) -> np.ndarray:
    """A valid descriptor: each histogram all in bin ``shift``."""
    d = np.zeros(SIZE)
    start = 0
    for size in (D2_BINS, D1_BINS, NORMAL_BINS, NORMAL_BINS, NORMAL_BINS):
        d[start + shift] = 1.0
        start += size
    return d


def build(root: Path) -> list[str]:
    """Two runs of synthetic rows (no files): the keys of the accepted shapes."""
    keys = []
    with open_catalogue(root) as cat:
        runs = {i: cat.create_run(i, 5, 20, {}, f"h{i}", 1, {}).id for i in (1, 2)}
        index = dict.fromkeys(runs, 0)
        rows = [(r, True, a) for r, *a in ACCEPTED] + [(r, False, a) for r, a in REJECTED]
        for run, accepted, info in rows:
            i = index[run]
            index[run] += 1
            spec = SurfaceSpec(
                f"x^2+y^2+z^2-{run}.{i}1", (-2, 2) * 3, (20,) * 3, provenance={"i": i}
            )
            row = {
                "key": spec.key,
                "spec": spec.to_json(),
                "formula": spec.formula,
                "identity": spec.key,
                "verdict": "accepted" if accepted else "rejected",
                "metrics": "{}",
            }
            if accepted:
                genus, comps, faces = info
                row |= {"reasons": "[]", "genus": genus, "components": comps, "faces": faces}
                row["descriptor"] = descriptor_to_text(_descriptor(len(keys)))
                keys.append(spec.key)
            else:
                row["reasons"] = json.dumps(info)
            cat.record_shape(runs[run], i, row, accepted, {})
    return keys


@pytest.fixture
def cat_dir(tmp_path) -> tuple[Path, list[str]]:
    root = tmp_path / "cat"
    return root, build(root)


def test_stats_over_all_runs_and_one(cat_dir) -> None:
    root, keys = cat_dir
    with open_catalogue(root, must_exist=True) as cat:
        apply_action(cat, keys[0], "star", 2)
        apply_action(cat, keys[1], "tag", ["nice"])
        apply_action(cat, keys[2], "reject", "meh")
        s = report_stats(cat)
        assert (s["drawn"], s["accepted"]) == (9, 5)
        assert s["acceptance"] == pytest.approx(5 / 9)
        assert s["reasons"] == {"noise": 2, "speckle": 1, "duplicate": 1, "empty": 1}
        assert sorted(s["genus"]) == [0, 1, 1, 3, 7]
        assert s["distinct_genus"] == 4 and s["distinct_genus_components"] == 5
        assert s["genus_entropy_bits"] == pytest.approx(
            -(3 * 0.2 * np.log2(0.2) + 0.4 * np.log2(0.4))
        )
        assert s["exact_duplicates"] == 1 and s["user_rejected"] == 1
        assert s["stars"] == {0: 4, 2: 1} and s["tags"] == {"nice": 1}
        assert s["descriptors"] == 5 and s["nearest_distance_median"] > 0
        one = report_stats(cat, run=2)
        assert (one["drawn"], one["accepted"], one["reasons"]) == (2, 1, {"empty": 1})
        assert one["scope"] == "run 2" and [r["id"] for r in one["runs"]] == [2]
        with pytest.raises(CatalogueError, match="no run 9"):
            report_stats(cat, run=9)


def test_html_is_self_contained(cat_dir, tmp_path) -> None:
    root, _ = cat_dir
    out = tmp_path / "r" / "report.html"
    assert main(["report", "-C", str(root), "-o", str(out)]) == 0
    text = out.read_text()
    images = re.findall(r"src='data:image/png;base64,([A-Za-z0-9+/=]+)'", text)
    # genus, components, faces, reasons, genus x components; solidity and genus of the one
    # family (shapes without a recorded family are "free"; no thumbnails: no contact sheet)
    assert len(images) == 7
    assert all(len(b) > 2000 for b in images)
    assert "http://" not in text and "https://" not in text and "<script" not in text
    for label in ("Genus of accepted shapes", "Acceptance by reason", "56%", "speckle"):
        assert label in text


def test_cli_defaults_and_errors(cat_dir, tmp_path, capsys) -> None:
    root, _ = cat_dir
    assert main(["report", "-C", str(root), "--run", "1"]) == 0
    assert (root / "report.html").is_file()
    assert "run 1" in (root / "report.html").read_text()
    capsys.readouterr()
    assert main(["report", "-C", str(root), "--run", "9"]) == 1
    assert capsys.readouterr().err == "error: no run 9 in the catalogue\n"
    assert main(["report", "-C", str(tmp_path / "none")]) == 1
    assert capsys.readouterr().err.startswith("error: no catalogue at")


def test_empty_catalogue_still_reports(tmp_path) -> None:
    with open_catalogue(tmp_path / "empty") as cat:
        s = report_stats(cat)
    assert s["drawn"] == 0 and s["nearest_distance_median"] is None
    html = render_report(s, "empty")
    assert html.count("data:image/png;base64,") == 5


def test_stats_and_report_per_family(tmp_path) -> None:
    from surfgen.pipelines.catalogue.curation import select_shapes

    root = tmp_path / "fam"
    # (family, accepted, free_standing, symmetry_permutations, solidity, genus, descriptor bin)
    shapes = [
        ("sculpture", True, True, 3, 0.8, 0, 0),
        ("sculpture", True, True, 1, 0.6, 2, 1),
        ("sculpture", True, False, 6, 0.9, 1, 2),
        ("sculpture", False, None, None, None, None, None),
        ("lattice", True, False, 3, 0.4, 9, 3),
        ("lattice", False, None, None, None, None, None),
        (None, True, None, None, None, 4, 4),  # a shape from before families: free
    ]
    with open_catalogue(root) as cat:
        run = cat.create_run(1, 5, 20, {}, "h", 2, {}).id
        for i, (fam, ok, free, perms, solid, genus, shift) in enumerate(shapes):
            spec = SurfaceSpec(f"x^2+y^2+z^2-{i + 1}", (-2, 2) * 3, (20,) * 3)
            model = {"terms": [], "d": 0.0} | ({"family": fam} if fam else {})
            metrics = {} if free is None else {"free_standing": free, "solidity": solid}
            if perms is not None:
                metrics["symmetry_permutations"] = perms
            row = {
                "key": spec.key,
                "spec": spec.to_json(),
                "formula": spec.formula,
                "identity": spec.key,
                "model": json.dumps(model),
                "verdict": "accepted" if ok else "rejected",
                "reasons": "[]" if ok else '["speckle"]',
                "metrics": json.dumps(metrics),
                "genus": genus,
            }
            if ok:
                row["descriptor"] = descriptor_to_text(_descriptor(shift))
            cat.record_shape(run, i, row, ok, {})
        s = report_stats(cat)
        fams = s["families"]
        assert set(fams) == {"sculpture", "lattice", "free"}
        sc = fams["sculpture"]
        assert (sc["drawn"], sc["accepted"], sc["free_standing"], sc["symmetric"]) == (4, 3, 2, 2)
        assert sc["acceptance"] == pytest.approx(0.75)
        assert sorted(sc["solidity"]) == [0.6, 0.8, 0.9] and sc["distinct_genus"] == 3
        assert fams["lattice"]["acceptance"] == pytest.approx(0.5)
        assert fams["free"]["accepted"] == 1
        assert (s["free_standing"], s["symmetric"]) == (2, 3)
        assert s["near_duplicate_rate"] == 0.0  # every descriptor in a bin of its own
        # --where and the gallery see the family and the quality metrics
        picked = select_shapes(cat, where="family = sculpture and free_standing = yes")
        assert len(picked) == 2 and {r["family"] for r in picked} == {"sculpture"}
        assert len(select_shapes(cat, where="family = free")) == 1
        assert len(select_shapes(cat, where="symmetry_permutations >= 3 and solidity < 0.85")) == 2
    html = render_report(s, str(root))
    for name in ("sculpture", "lattice", "free"):
        assert f"Family: {name}" in html
    assert "free-standing" in html and "permutation symmetry" in html


def test_vendi_blobs_and_resolution(tmp_path) -> None:
    root = tmp_path / "vendi"
    # (accepted, descriptor bin, genus, components, metrics, reasons)
    shapes = [
        (True, 0, 0, 1, {"solidity": 0.95, "resolution_shift": 0.2}, []),  # a convex blob
        (True, 0, 0, 1, {"solidity": 0.7, "resolution_shift": 0.4}, []),  # same descriptor
        (True, 5, 1, 1, {"solidity": 0.95, "resolution_shift": 0.1}, []),  # genus 1: no blob
        (True, 9, 0, 2, {"solidity": 0.99}, []),  # two pieces: no blob; not measured
        (False, None, None, None, {}, ["unresolved"]),
        (False, None, None, None, {}, ["unresolved", "walls"]),
        (False, None, None, None, {}, ["speckle"]),
    ]
    with open_catalogue(root) as cat:
        run = cat.create_run(1, 7, 20, {}, "h", 2, {}).id
        for i, (ok, shift, genus, comps, metrics, reasons) in enumerate(shapes):
            spec = SurfaceSpec(f"x^2+y^2+z^2-{i + 1}", (-2, 2) * 3, (20,) * 3)
            row = {
                "key": spec.key,
                "spec": spec.to_json(),
                "formula": spec.formula,
                "identity": spec.key,
                "model": json.dumps({"terms": [], "d": 0.0, "family": "sculpture"}),
                "verdict": "accepted" if ok else "rejected",
                "reasons": json.dumps(reasons),
                "metrics": json.dumps(metrics),
                "genus": genus,
                "components": comps,
            }
            if ok:
                row["descriptor"] = descriptor_to_text(_descriptor(shift))
            cat.record_shape(run, i, row, ok, {})
        s = report_stats(cat)
    # as stored: rounded histograms, 8-bit placement
    rows = np.array(
        [descriptor_from_text(descriptor_to_text(_descriptor(b))) for b in (0, 0, 5, 9)]
    )
    assert s["vendi"] == pytest.approx(descriptor_vendi(rows))
    assert 2.0 < s["vendi"] < 3.5  # two alike, two apart
    assert s["vendi_bandwidth"] == BANDWIDTH
    assert s["blobs"] == 1 and s["unresolved"] == 2
    assert sorted(s["resolution_shift"]) == [0.1, 0.2, 0.4]
    sc = s["families"]["sculpture"]
    assert sc["vendi"] == pytest.approx(s["vendi"]) and sc["blobs"] == 1
    assert sc["unresolved"] == 2
    html = render_report(s, str(root))
    assert "Vendi score" in html and f"{s['vendi']:.1f}" in html
    assert "convex blobs" in html and "25%" in html  # 1 of 4 accepted
    assert "rejected as unresolved" in html and "median resolution shift" in html
