"""How diverse is the catalogue? A self-contained HTML report (``surfgen report``).

:func:`report_stats` counts, over one run or the whole catalogue: draws, acceptance, rejection
reasons, the distributions of genus, components and faces of the accepted shapes, curation
(stars, tags, rejections, near duplicates) and a few diversity numbers. :func:`render_report`
draws the histograms with matplotlib (Agg) as PNGs embedded in base64, so the one HTML file
can be mailed or published as it is.
"""

from __future__ import annotations

import base64
import html
import io
import json
import logging
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from surfgen.filters.descriptor import DEFAULT_THRESHOLD, descriptor_from_text, nearest_distances
from surfgen.filters.diversity import BANDWIDTH, descriptor_vendi
from surfgen.pipelines.catalogue.store import Catalogue, now, open_catalogue
from surfgen.pipelines.web.pages import write_page

log = logging.getLogger(__name__)

_BLUE = "#2f6f8f"
_RED = "#b3402e"
_GREY = "#9aa0a6"


# ----------------------------------------------------------------------------- numbers


def _entropy_bits(counts: Counter) -> float:
    total = sum(counts.values())
    if total == 0:
        return 0.0
    p = np.array([c / total for c in counts.values()])
    return float(-(p * np.log2(p)).sum())


def _descriptors_by_key(cat: Catalogue, keys: list[str]) -> dict[str, np.ndarray]:
    """The stored descriptors of the accepted shapes ``keys`` (those of another version are
    left out)."""
    wanted = set(keys)
    rows = cat.conn.execute("SELECT key, descriptor FROM shapes WHERE verdict='accepted'")
    out = {}
    for r in rows:
        if r["key"] in wanted and (d := descriptor_from_text(r["descriptor"])) is not None:
            out[r["key"]] = d
    return out


def _nearest_by_key(descriptors: dict[str, np.ndarray]) -> dict[str, float]:
    """Each shape's descriptor distance to its nearest other shape."""
    if len(descriptors) < 2:
        return {}
    nearest = nearest_distances(np.array(list(descriptors.values())))
    return {key: float(dist) for key, dist in zip(descriptors, nearest, strict=True)}


def _vendi(descriptors: dict[str, np.ndarray], keys: list[str]) -> float | None:
    """The Vendi score (:mod:`surfgen.filters.diversity`) of the shapes ``keys`` that have a
    descriptor; None when none has."""
    rows = [descriptors[k] for k in keys if k in descriptors]
    return descriptor_vendi(np.array(rows)) if rows else None


def is_blob(row: dict[str, Any], metrics: dict[str, Any]) -> bool:
    """A convex blob as issue 40 counts them: one piece of genus 0 filling at least
    :data:`BLOB_SOLIDITY` of its convex hull."""
    solidity = metrics.get("solidity")
    return (
        row["genus"] == 0
        and row["components"] == 1
        and solidity is not None
        and solidity >= BLOB_SOLIDITY
    )


BLOB_SOLIDITY = 0.9


def family_of(row: dict[str, Any]) -> str:
    """The sampler family recorded in a shape's model (shapes from before families: free)."""
    try:
        return str(json.loads(row.get("model") or "{}").get("family", "free"))
    except (json.JSONDecodeError, AttributeError):
        return "free"


SHEET_SHAPES = 24  # thumbnails per family on the report's contact sheets


def _family_stats(
    rows: list[dict[str, Any]], nearest: dict[str, float], descriptors: dict[str, np.ndarray]
) -> dict[str, Any]:
    """Acceptance, free-standing and symmetric shares, solidity and genus, convex blobs,
    resolution, diversity (nearest distances, Vendi score)."""
    accepted = [r for r in rows if r["verdict"] == "accepted"]
    metrics = [json.loads(r["metrics"] or "{}") for r in accepted]
    n = len(accepted)
    genus = [r["genus"] for r in accepted if r["genus"] is not None]
    near = [nearest[r["key"]] for r in accepted if r["key"] in nearest]
    shifts = [m["resolution_shift"] for m in metrics if m.get("resolution_shift") is not None]
    return {
        "drawn": len(rows),
        "accepted": n,
        "acceptance": n / len(rows) if rows else 0.0,
        "free_standing": sum(1 for m in metrics if m.get("free_standing") is True),
        "symmetric": sum(1 for m in metrics if (m.get("symmetry_permutations") or 1) > 1),
        "mirrored": sum(1 for m in metrics if (m.get("symmetry_mirrors") or 0) > 0),
        "solidity": [m["solidity"] for m in metrics if m.get("solidity") is not None],
        "genus": genus,
        "distinct_genus": len(set(genus)),
        "nearest_distance_median": float(np.median(near)) if near else None,
        "near_duplicate_rate": float(np.mean(np.array(near) < DEFAULT_THRESHOLD)) if near else None,
        "vendi": _vendi(descriptors, [r["key"] for r in accepted]),
        "blobs": sum(1 for r, m in zip(accepted, metrics, strict=True) if is_blob(r, m)),
        "unresolved": sum(1 for r in rows if "unresolved" in json.loads(r["reasons"] or "[]")),
        "resolution_shift": shifts,
        "thumbs": [
            (r["thumb_path"], r["key"][:8]) for r in accepted[:SHEET_SHAPES] if r["thumb_path"]
        ],
    }


def report_stats(cat: Catalogue, run: int | None = None) -> dict[str, Any]:
    """Counts and distributions over run ``run`` (or every run). Raises :class:`CatalogueError`
    for an unknown run."""
    if run is not None:
        cat.get_run(run)  # raises for an unknown run
    rows = [dict(r) for r in cat.shapes(run_id=run)]
    accepted = [r for r in rows if r["verdict"] == "accepted"]
    reasons: Counter[str] = Counter()
    for r in rows:
        if r["verdict"] != "accepted":
            reasons.update(json.loads(r["reasons"] or "[]"))
    keys = [r["key"] for r in accepted]
    wanted = set(keys)
    tag_rows = cat.conn.execute("SELECT key, tag FROM tags").fetchall()
    tags = Counter(t["tag"] for t in tag_rows if t["key"] in wanted)
    genus = Counter(r["genus"] for r in accepted if r["genus"] is not None)
    pairs = {(r["genus"], r["components"]) for r in accepted}
    descriptors = _descriptors_by_key(cat, keys)
    nearest_by_key = _nearest_by_key(descriptors)
    nearest = list(nearest_by_key.values())
    families: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        families.setdefault(family_of(r), []).append(r)
    everything = _family_stats(rows, nearest_by_key, descriptors)
    runs = [r for r in cat.runs() if run is None or r["id"] == run]
    return {
        "scope": f"run {run}" if run is not None else "all runs",
        "drawn": len(rows),
        "accepted": len(accepted),
        "acceptance": len(accepted) / len(rows) if rows else 0.0,
        "reasons": dict(reasons.most_common()),
        "genus": [r["genus"] for r in accepted if r["genus"] is not None],
        "open": sum(1 for r in accepted if r["genus"] is None),
        "components": [r["components"] for r in accepted if r["components"] is not None],
        "faces": [r["faces"] for r in accepted if r["faces"] is not None],
        "genus_components": [
            (r["genus"], r["components"]) for r in accepted if r["genus"] is not None
        ],
        "stars": dict(sorted(Counter(r["stars"] or 0 for r in accepted).items())),
        "user_rejected": sum(1 for r in accepted if r["user_rejected"]),
        "near_duplicates": sum(1 for r in accepted if r["duplicate_of"]),
        "exact_duplicates": reasons.get("duplicate", 0),
        "tags": dict(tags.most_common()),
        "distinct_genus": len(genus),
        "distinct_genus_components": len(pairs),
        "genus_entropy_bits": _entropy_bits(genus),
        "nearest_distance_median": float(np.median(nearest)) if nearest else None,
        "descriptors": len(nearest),
        "free_standing": everything["free_standing"],
        "symmetric": everything["symmetric"],
        "near_duplicate_rate": everything["near_duplicate_rate"],
        "solidity": everything["solidity"],
        "vendi": everything["vendi"],
        "vendi_bandwidth": BANDWIDTH,
        "blobs": everything["blobs"],
        "unresolved": everything["unresolved"],
        "resolution_shift": everything["resolution_shift"],
        "families": {
            name: _family_stats(family_rows, nearest_by_key, descriptors)
            for name, family_rows in sorted(families.items())
        },
        "runs": [
            {
                "id": r["id"],
                "seed": r["seed"],
                "grid": r["grid"],
                "drawn": r["next_index"],
                "accepted": r["accepted"],
                "status": r["status"],
                "started": r["started"],
            }
            for r in runs
        ],
    }


# ----------------------------------------------------------------------------- figures


def _figure_png(draw) -> str:
    """Run ``draw(ax)`` on a fresh Agg figure; return the PNG as a base64 data URI."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(5.2, 3.2), dpi=110, layout="constrained")
    ax = fig.subplots()
    ax.spines[["top", "right"]].set_visible(False)
    draw(ax)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _int_hist(values: list[int], what: str):
    def draw(ax) -> None:
        if not values:
            ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
            return
        lo, hi = min(values), max(values)
        if hi - lo <= 40:  # one bar per value
            counts = Counter(values)
            xs = list(range(lo, hi + 1))
            ax.bar(xs, [counts.get(x, 0) for x in xs], width=0.85, color=_BLUE)
        else:
            edges = np.unique(np.linspace(lo, hi + 1, 31).round())
            ax.hist(values, bins=edges, color=_BLUE, edgecolor="white")
        ax.set_xlabel(what)
        ax.set_ylabel("shapes")
        ax.yaxis.get_major_locator().set_params(integer=True)

    return draw


def _faces_hist(values: list[int]):
    def draw(ax) -> None:
        if not values:
            ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
            return
        lo, hi = max(min(values), 1), max(values)
        edges = np.geomspace(lo, hi * 1.001 if hi > lo else lo * 2, 25)
        ax.hist(values, bins=edges, color=_BLUE, edgecolor="white")
        ax.set_xscale("log")
        ax.set_xlabel("faces (log scale)")
        ax.set_ylabel("shapes")
        ax.yaxis.get_major_locator().set_params(integer=True)

    return draw


def _reasons_bar(accepted: int, reasons: dict[str, int]):
    def draw(ax) -> None:
        names = ["accepted", *reasons]
        counts = [accepted, *reasons.values()]
        colours = [_BLUE] + [_RED] * len(reasons)
        ys = np.arange(len(names))[::-1]
        ax.barh(ys, counts, color=colours)
        ax.set_yticks(ys, names)
        for y, c in zip(ys, counts, strict=True):
            ax.text(c, y, f" {c}", va="center", fontsize=8)
        ax.set_xlabel("draws (a rejected draw may have several reasons)")
        ax.margins(x=0.12)

    return draw


def _scatter(genus_components: list[tuple[int, int]]):
    def draw(ax) -> None:
        if not genus_components:
            ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
            return
        pairs = Counter(genus_components)
        xs, ys, ns = zip(*((g, c, n) for (g, c), n in pairs.items()), strict=True)
        ax.scatter(xs, ys, s=[18 + 14 * n for n in ns], color=_BLUE, alpha=0.6, edgecolor="white")
        ax.set_xlabel("genus")
        ax.set_ylabel("components")
        ax.set_xscale("symlog", linthresh=10)
        ax.set_yscale("symlog", linthresh=10)

    return draw


# ----------------------------------------------------------------------------- HTML

_CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,Arial,sans-serif;color:#22252a;
background:#f4f3ef;margin:0;padding:24px 32px;font-size:14px}
h1{font-size:22px;margin:0 0 4px}h2{font-size:15px;margin:28px 0 10px;text-transform:uppercase;
letter-spacing:.05em;color:#6b7078}.sub{color:#6b7078;margin:0}
.cards{display:flex;flex-wrap:wrap;gap:12px;margin-top:18px}
.card{background:#fff;border-radius:10px;padding:12px 16px;min-width:130px;box-shadow:0 1px 3px rgba(0,0,0,.08)}
.card b{display:block;font-size:22px}.card span{color:#6b7078;font-size:12px}
.figs{display:grid;grid-template-columns:repeat(auto-fill,minmax(460px,1fr));gap:14px}
figure{background:#fff;margin:0;border-radius:10px;padding:10px;box-shadow:0 1px 3px rgba(0,0,0,.08)}
figure img{width:100%;height:auto}figure.sheet{grid-column:1/-1}figcaption{font-weight:600;margin:2px 4px 6px}
table{border-collapse:collapse;background:#fff;border-radius:8px;overflow:hidden}
td,th{padding:5px 12px;border-bottom:1px solid #eee;text-align:right}th{background:#fafaf8}
td:first-child,th:first-child{text-align:left}.tags span{display:inline-block;background:#e7f0f4;
color:#24556d;border-radius:10px;padding:1px 9px;margin:2px;font-size:12px}
"""


def _card(value: Any, label: str) -> str:
    return (
        f"<div class='card'><b>{html.escape(str(value))}</b><span>{html.escape(label)}</span></div>"
    )


def _float_hist(values: list[float], what: str):
    def draw(ax) -> None:
        if not values:
            ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
            return
        ax.hist(values, bins=np.linspace(0.0, 1.0, 21), color=_BLUE, edgecolor="white")
        ax.set_xlabel(what)
        ax.set_ylabel("shapes")
        ax.yaxis.get_major_locator().set_params(integer=True)

    return draw


def _sheet_uri(root: Path | None, thumbs: list[tuple[str, str]]) -> str | None:
    """A contact sheet of the thumbnails as a PNG data URI (None without thumbnails)."""
    import tempfile

    from surfgen.pipelines.pictures.raster import contact_sheet

    items = [(root / path, label) for path, label in thumbs if root is not None]
    items = [(p, label) for p, label in items if p.exists()]
    if not items:
        return None
    with tempfile.TemporaryDirectory() as tmp:
        out = contact_sheet(items, Path(tmp) / "sheet.png", columns=8, label_size=11)
        data = out.read_bytes()
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


def _number(value: float | None) -> str:
    return "–" if value is None else f"{value:.1f}"


def _median(values: list[float]) -> str:
    return f"{np.median(values):.2f}" if values else "–"


def _pct(part: int, whole: int) -> str:
    return f"{100 * part / whole:.0f}%" if whole else "–"


def _families_html(s: dict[str, Any], root: Path | None) -> str:
    """A table of the families and, per family, histograms and a contact sheet."""
    fams = s.get("families") or {}
    if not fams:
        return ""
    rows = []
    for name, f in fams.items():
        solid = f"{np.median(f['solidity']):.2f}" if f["solidity"] else "–"
        near = f["nearest_distance_median"]
        rate = f["near_duplicate_rate"]
        rows.append(
            f"<tr><td>{html.escape(name)}</td><td>{f['drawn']}</td><td>{f['accepted']}</td>"
            f"<td>{_pct(f['accepted'], f['drawn'])}</td>"
            f"<td>{_pct(f['free_standing'], f['accepted'])}</td>"
            f"<td>{_pct(f['symmetric'], f['accepted'])}</td>"
            f"<td>{f['distinct_genus']}</td>"
            f"<td>{solid}</td>"
            f"<td>{'–' if near is None else f'{near:.3f}'}</td>"
            f"<td>{'–' if rate is None else f'{100 * rate:.1f}%'}</td>"
            f"<td>{_number(f['vendi'])}</td>"
            f"<td>{_pct(f['blobs'], f['accepted'])}</td>"
            f"<td>{_pct(f['unresolved'], f['drawn'])}</td>"
            f"<td>{_median(f['resolution_shift'])}</td></tr>"
        )
    out = [
        "<h2>Families</h2><table><tr><th>family</th><th>draws</th><th>accepted</th>"
        "<th>acceptance</th><th>free-standing</th><th>permutation symmetry</th>"
        "<th>distinct genera</th><th>median solidity</th><th>median nearest distance</th>"
        "<th>near duplicates</th><th>Vendi score</th><th>convex blobs</th>"
        "<th>rejected unresolved (of draws)</th><th>median resolution shift (cells)</th>"
        f"</tr>{''.join(rows)}</table>"
    ]
    for name, f in fams.items():
        if not f["accepted"]:
            continue
        figures = [
            (f"{name}: solidity", _float_hist(f["solidity"], "volume / convex hull volume")),
            (f"{name}: genus", _int_hist(f["genus"], "genus")),
        ]
        figs = "".join(
            f"<figure><figcaption>{html.escape(title)}</figcaption>"
            f"<img alt='{html.escape(title)}' src='{_figure_png(draw)}'></figure>"
            for title, draw in figures
        )
        sheet = _sheet_uri(root, f["thumbs"])
        if sheet is not None:
            caption = f"{name}: the first {len(f['thumbs'])} accepted shapes"
            figs += (
                f"<figure class='sheet'><figcaption>{html.escape(caption)}</figcaption>"
                f"<img alt='{html.escape(caption)}' src='{sheet}'></figure>"
            )
        out.append(f"<h2>Family: {html.escape(name)}</h2><div class='figs'>{figs}</div>")
    return "".join(out)


def render_report(stats: dict[str, Any], catalogue: str) -> str:
    """The report page for ``stats`` (from :func:`report_stats`): one HTML string; the
    families' contact sheets are drawn from the thumbnails under ``catalogue``."""
    s = stats
    figures = [
        ("Genus of accepted shapes", _int_hist(s["genus"], "genus")),
        ("Components of accepted shapes", _int_hist(s["components"], "components")),
        ("Faces of accepted shapes", _faces_hist(s["faces"])),
        ("Acceptance by reason", _reasons_bar(s["accepted"], s["reasons"])),
        (
            "Genus × components (dot size: shapes)",
            _scatter(s["genus_components"]),
        ),
    ]
    figs = "".join(
        f"<figure><figcaption>{html.escape(title)}</figcaption>"
        f"<img alt='{html.escape(title)}' src='{_figure_png(draw)}'></figure>"
        for title, draw in figures
    )
    near = s["nearest_distance_median"]
    accepted = s["accepted"]
    rate = s.get("near_duplicate_rate")
    cards = "".join(
        [
            _card(_pct(s.get("free_standing", 0), accepted), "free-standing"),
            _card(_pct(s.get("symmetric", 0), accepted), "with a permutation symmetry"),
            _card(
                "–" if rate is None else f"{100 * rate:.1f}%",
                "near duplicates (nearest shape closer than 1)",
            ),
            _card(
                _number(s.get("vendi")),
                f"Vendi score: effective number of distinct shapes (descriptor kernel, "
                f"bandwidth {s.get('vendi_bandwidth', BANDWIDTH):g})",
            ),
            _card(
                _pct(s.get("blobs", 0), accepted),
                "convex blobs (genus 0, one piece, solidity ≥ 0.9)",
            ),
            _card(s.get("unresolved", 0), "rejected as unresolved (twice-as-fine grid)"),
            _card(_median(s.get("resolution_shift", [])), "median resolution shift (cells)"),
            _card(s["drawn"], "draws"),
            _card(s["accepted"], "accepted"),
            _card(f"{100 * s['acceptance']:.0f}%", "acceptance"),
            _card(s["distinct_genus"], "distinct genera"),
            _card(s["distinct_genus_components"], "distinct (genus, components)"),
            _card(f"{s['genus_entropy_bits']:.2f}", "genus entropy (bits)"),
            _card("–" if near is None else f"{near:.3f}", "median nearest-shape distance"),
            _card(s["near_duplicates"], "near duplicates marked (catalogue dedupe)"),
            _card(s["exact_duplicates"], "duplicates rejected while sampling (exact or near)"),
            _card(s["user_rejected"], "rejected by curators"),
            _card(sum(n for k, n in s["stars"].items() if k), "starred"),
        ]
    )
    run_rows = "".join(
        f"<tr><td>{r['id']}</td><td>{r['seed']}</td><td>{r['grid']}</td><td>{r['drawn']}</td>"
        f"<td>{r['accepted']}</td><td>{100 * r['accepted'] / max(r['drawn'], 1):.0f}%</td>"
        f"<td>{html.escape(r['status'])}</td><td>{html.escape(r['started'] or '')}</td></tr>"
        for r in s["runs"]
    )
    reason_rows = (
        "".join(
            f"<tr><td>{html.escape(k)}</td><td>{n}</td><td>{100 * n / max(s['drawn'], 1):.1f}%</td></tr>"
            for k, n in s["reasons"].items()
        )
        or "<tr><td colspan='3'>no rejected draws</td></tr>"
    )
    tags = (
        "".join(f"<span>{html.escape(t)} · {n}</span>" for t, n in list(s["tags"].items())[:40])
        or "<span>no tags yet</span>"
    )
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>surfgen report — {html.escape(s["scope"])}</title>
<meta name="viewport" content="width=device-width, initial-scale=1"><style>{_CSS}</style></head>
<body><h1>surfgen catalogue report</h1>
<p class="sub">{html.escape(catalogue)} · {html.escape(s["scope"])} · {html.escape(now())}
{f" · {s['open']} open shapes have no genus" if s["open"] else ""}</p>
<div class="cards">{cards}</div>
<h2>Distributions</h2><div class="figs">{figs}</div>
{_families_html(s, Path(catalogue))}
<h2>Rejection reasons</h2><table><tr><th>reason</th><th>draws</th><th>of all draws</th></tr>
{reason_rows}</table>
<h2>Runs</h2><table><tr><th>run</th><th>seed</th><th>grid</th><th>draws</th><th>accepted</th>
<th>acceptance</th><th>status</th><th>started</th></tr>{run_rows}</table>
<h2>Tags</h2><p class="tags">{tags}</p>
</body></html>
"""


def write_report(root: Path, path: Path | None = None, run: int | None = None) -> Path:
    """Write the report of the catalogue at ``root`` (default ``root/report.html``)."""
    with open_catalogue(root, readonly=True) as cat:
        stats = report_stats(cat, run)
    path = Path(path) if path is not None else Path(root) / "report.html"
    path.parent.mkdir(parents=True, exist_ok=True)
    write_page(path, render_report(stats, str(root)))
    log.info("report of %d shapes written to %s", stats["accepted"], path)
    return path
