"""surfgen.pipelines.cli.main."""
