"""``surfgen dataset ...``: the catalogue as a machine-learning dataset.

The export and the check (numba, trimesh; pyarrow for Parquet) are imported when a command runs
(``# deferred``), so that ``--help`` and the other commands do not load them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from surfgen.generator.formula.limits import parse_size
from surfgen.generator.mesh.formats import DATASET_FORMATS
from surfgen.pipelines.catalogue.store import DEFAULT_CATALOGUE
from surfgen.pipelines.cli.common import CatalogueOption

dataset_app = typer.Typer(
    no_args_is_help=True, help="The catalogue as a machine-learning dataset (WebDataset, Parquet)."
)


@dataset_app.command("export")
def export_cmd(
    output: Annotated[Path, typer.Option("-o", "--output", help="A new or empty folder.")],
    catalogue: CatalogueOption = DEFAULT_CATALOGUE,
    where: Annotated[
        str | None, typer.Option(help="Which accepted shapes (as `catalogue list --where`).")
    ] = None,
    shard_size: Annotated[
        int | None, typer.Option(help="Samples per tar shard (default 1000).", show_default=False)
    ] = None,
    max_shard_bytes: Annotated[
        str | None,
        typer.Option(
            help="Bytes per tar shard instead, e.g. 500M or 1G (a few hundred MB to 1 GB suits "
            "the Hugging Face Hub); a shard is larger only if one sample alone is.",
            show_default=False,
        ),
    ] = None,
    points: Annotated[
        int, typer.Option(help="Surface points with normals per shape (0: none).")
    ] = 0,
    sdf: Annotated[int, typer.Option(help="Field samples in the box per shape (0: none).")] = 0,
    fmt: Annotated[
        str, typer.Option("--format", help=f"Mesh format: {' or '.join(DATASET_FORMATS)}.")
    ] = "ply",
    license_: Annotated[
        str, typer.Option("--license", help="License identifier for the dataset card.")
    ] = "mit",
) -> None:
    """Write WebDataset shards, metadata.parquet, a dataset card and croissant.json for the
    accepted shapes."""
    from surfgen.pipelines.export.dataset import DatasetOptions, export_dataset  # deferred

    limit = (
        parse_size(max_shard_bytes, "--max-shard-bytes") if max_shard_bytes is not None else None
    )
    options = DatasetOptions(where, shard_size, points, sdf, fmt.lower(), license_, limit)
    s = export_dataset(catalogue, output, options)
    typer.echo(
        f"{s.shapes} shapes in {s.shards} shard(s) (largest {max(s.shard_bytes) / 1e6:.1f} MB), "
        f"{s.bytes / 1e6:.1f} MB of members "
        f"(train {s.splits['train']}, val {s.splits['val']}, test {s.splits['test']}) -> {s.out}"
    )


@dataset_app.command("verify")
def verify_cmd(
    folder: Annotated[Path, typer.Argument(help="A folder written by `surfgen dataset export`.")],
    sample: Annotated[int, typer.Option(help="How many rows to regenerate.")] = 20,
    seed: Annotated[int, typer.Option(help="Seed of the choice of rows.")] = 0,
) -> None:
    """Regenerate rows from their recipes; compare keys, metrics and file hashes."""
    from surfgen.pipelines.export.dataset_verify import verify_dataset  # deferred

    report = verify_dataset(folder, sample, seed)
    for p in report.problems:
        typer.echo(p)
    typer.echo(
        f"{len(report.checked)} of {report.rows} rows regenerated: "
        + ("all agree" if report.ok else f"{len(report.problems)} disagreement(s)")
    )
    if not report.ok:
        raise typer.Exit(1)
