"""surfgen.pipelines.catalogue.store."""
