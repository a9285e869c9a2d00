"""surfgen.pipelines: sampling runs, the catalogue, curation, export and the CLI."""
