"""surfgen.pipelines.pictures.raster."""
