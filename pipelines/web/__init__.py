"""surfgen.pipelines.web."""
