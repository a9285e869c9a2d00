"""``surfgen catalogue ...``: list, show and curate the catalogue's shapes, mark near
duplicates, check and repair the catalogue. Listing, showing and curating are
:class:`surfgen.Catalogue`'s; every change goes through
:func:`surfgen.pipelines.catalogue.curation.apply_action`."""

from __future__ import annotations

from typing import Annotated, Any

import typer

from surfgen import Catalogue
from surfgen.generator.formula.limits import MAX_STARS
from surfgen.pipelines.catalogue.curation import dedupe_catalogue
from surfgen.pipelines.catalogue.store import DEFAULT_CATALOGUE, open_catalogue
from surfgen.pipelines.cli.common import CatalogueOption, emit_json

catalogue_app = typer.Typer(no_args_is_help=True, help="Browse and curate the catalogue.")


def _num(v: Any, fmt: str = "g") -> str:
    return "-" if v is None else format(v, fmt)


def _flags(rec: dict[str, Any]) -> str:
    out = []
    if rec["verdict"] != "accepted":
        out.append("filtered:" + ",".join(rec["reasons"]))
    if rec["rejected"]:
        out.append("rejected")
    if rec["duplicate_of"]:
        out.append(f"dup:{rec['duplicate_of'][:8]}")
    return " ".join(out)


@catalogue_app.command("list")
def list_cmd(
    catalogue: CatalogueOption = DEFAULT_CATALOGUE,
    where: Annotated[
        str | None, typer.Option(help="Filter, e.g. 'genus >= 2 and tag = nice'.")
    ] = None,
    sort: Annotated[
        str | None, typer.Option(help="FIELD or -FIELD (descending), comma-separated.")
    ] = None,
    limit: Annotated[int | None, typer.Option(help="At most this many shapes.")] = None,
    everything: Annotated[
        bool, typer.Option("--all", help="Include the draws the filters rejected.")
    ] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON records.")] = False,
) -> None:
    """List shapes, filtered and sorted by their metrics, tags and curation."""
    found = Catalogue(catalogue).query(where, sort, limit=limit, everything=everything)
    recs = [r.to_dict() for r in found]
    if as_json:
        emit_json(recs)
        return
    typer.echo(
        f"{'key':<16} {'run':>3} {'index':>5} {'genus':>5} {'comp':>4} {'faces':>7} "
        f"{'area':>8}  {'stars':<5} tags"
    )
    for r in recs:
        stars = "*" * r["stars"] or "-"
        extra = " ".join(filter(None, [",".join(r["tags"]), _flags(r)]))
        typer.echo(
            f"{r['key']:<16} {r['run']:>3} {r['index']:>5} {_num(r['genus']):>5} "
            f"{_num(r['components']):>4} {_num(r['faces']):>7} {_num(r['area'], '.4g'):>8}  "
            f"{stars:<5} {extra}".rstrip()
        )
    typer.echo(f"{len(recs)} shape{'s' if len(recs) != 1 else ''}", err=True)


@catalogue_app.command("show")
def show_cmd(
    key: Annotated[str, typer.Argument(help="Shape key or unique prefix.")],
    catalogue: CatalogueOption = DEFAULT_CATALOGUE,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Everything about one shape: formula, spec, metrics, curation, files, provenance."""
    rec = Catalogue(catalogue)[key].to_dict()
    if as_json:
        emit_json(rec)
        return
    prov = rec["provenance"]
    lines = [
        f"key        {rec['key']}",
        f"formula    {rec['formula']}",
        f"box        {rec['spec'].get('box')}   grid {rec['spec'].get('grid')}   level {rec['spec'].get('level')}",
        f"verdict    {rec['verdict']}"
        + (f" ({', '.join(rec['reasons'])})" if rec["reasons"] else ""),
        f"run        {rec['run']}  index {rec['index']}  seed {prov.get('seed')}  "
        f"sampler {prov.get('sampler')}  config {prov.get('config')}",
        f"stars      {rec['stars']}",
        f"tags       {' '.join(rec['tags']) or '-'}",
        f"rejected   {rec['rejected'] or '-'}",
        f"note       {rec['note'] or '-'}",
        f"duplicate  {rec['duplicate_of'] or '-'}",
        f"files      {', '.join(p for p in (rec['mesh'], rec['thumb'], rec['turntable']) if p) or '-'}",
        "metrics",
    ]
    lines += [f"  {k:<28} {v}" for k, v in sorted(rec["metrics"].items())]
    typer.echo("\n".join(lines))


def _report(rec: dict[str, Any]) -> None:
    typer.echo(
        f"{rec['key']}: stars {rec['stars']}, tags {' '.join(rec['tags']) or '-'}"
        f", rejected {rec['rejected'] or '-'}, note {rec['note'] or '-'}"
    )


@catalogue_app.command("star")
def star_cmd(
    key: Annotated[str, typer.Argument(help="Shape key or unique prefix.")],
    stars: Annotated[int, typer.Argument(help=f"Stars 0-{MAX_STARS} (0 removes them).")] = 1,
    catalogue: CatalogueOption = DEFAULT_CATALOGUE,
) -> None:
    """Give a shape stars."""
    _report(Catalogue(catalogue).star(key, stars).to_dict())


@catalogue_app.command("reject")
def reject_cmd(
    key: Annotated[str, typer.Argument(help="Shape key or unique prefix.")],
    why: Annotated[str, typer.Option("--why", help="Why it is rejected (required).")],
    catalogue: CatalogueOption = DEFAULT_CATALOGUE,
) -> None:
    """Reject a shape by hand (it stays in the catalogue, hidden from the gallery)."""
    _report(Catalogue(catalogue).reject(key, why).to_dict())


@catalogue_app.command("unreject")
def unreject_cmd(
    key: Annotated[str, typer.Argument(help="Shape key or unique prefix.")],
    catalogue: CatalogueOption = DEFAULT_CATALOGUE,
) -> None:
    """Undo a curator's rejection."""
    _report(Catalogue(catalogue).unreject(key).to_dict())


@catalogue_app.command("tag")
def tag_cmd(
    key: Annotated[str, typer.Argument(help="Shape key or unique prefix.")],
    tags: Annotated[list[str], typer.Argument(help="One or more tags.")],
    catalogue: CatalogueOption = DEFAULT_CATALOGUE,
) -> None:
    """Add tags to a shape."""
    _report(Catalogue(catalogue).tag(key, *tags).to_dict())


@catalogue_app.command("untag")
def untag_cmd(
    key: Annotated[str, typer.Argument(help="Shape key or unique prefix.")],
    tags: Annotated[list[str], typer.Argument(help="One or more tags.")],
    catalogue: CatalogueOption = DEFAULT_CATALOGUE,
) -> None:
    """Remove tags from a shape."""
    _report(Catalogue(catalogue).untag(key, *tags).to_dict())


@catalogue_app.command("note")
def note_cmd(
    key: Annotated[str, typer.Argument(help="Shape key or unique prefix.")],
    text: Annotated[str, typer.Argument(help="The note ('' removes it).")],
    catalogue: CatalogueOption = DEFAULT_CATALOGUE,
) -> None:
    """Write a note on a shape."""
    _report(Catalogue(catalogue).note(key, text).to_dict())


@catalogue_app.command("dedupe")
def dedupe_cmd(
    catalogue: CatalogueOption = DEFAULT_CATALOGUE,
    threshold: Annotated[
        float | None,
        typer.Option(
            help="Descriptor distance below which shapes are duplicates (in units of the calibrated scales; default 1)."
        ),
    ] = None,
    dry_run: Annotated[bool, typer.Option(help="Report, change nothing.")] = False,
) -> None:
    """Mark near-duplicate shapes (close shape descriptors) with the key they copy."""
    with open_catalogue(catalogue, must_exist=True) as cat:
        res = dedupe_catalogue(cat, threshold, dry_run=dry_run)
    for key, of, dist in res.marked:
        typer.echo(f"{key} duplicates {of} (distance {dist:.4f})")
    typer.echo(
        f"{len(res.marked)} near duplicate{'s' if len(res.marked) != 1 else ''} among {res.checked} "
        f"accepted shapes ({res.computed} descriptors computed"
        + (f", {len(res.missing)} without mesh" if res.missing else "")
        + ")"
        + (" — dry run, nothing written" if dry_run else "")
    )


@catalogue_app.command("check")
def check_cmd(
    catalogue: CatalogueOption = DEFAULT_CATALOGUE,
    repair: Annotated[
        bool,
        typer.Option(help="Rebuild what can be rebuilt (database rows, files from specs)."),
    ] = False,
) -> None:
    """Check a catalogue: database integrity, files against rows, orphans; --repair mends."""
    # Deferred: rebuilding files loads the evaluator and the mesher (numba, trimesh).
    from surfgen.pipelines.catalogue.check import check_catalogue

    report = check_catalogue(
        catalogue, repair=repair, progress=lambda key: typer.echo(f"rebuilding {key}", err=True)
    )
    for line in report.lines():
        typer.echo(line)
    left = report.problems + len(report.unrepaired)
    if left and not repair:
        typer.echo("run `surfgen catalogue check --repair` to mend what can be rebuilt")
    if left:
        raise typer.Exit(1)
