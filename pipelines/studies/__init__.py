"""surfgen.pipelines.studies."""
