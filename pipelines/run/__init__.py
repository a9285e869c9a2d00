"""surfgen.pipelines.run."""
