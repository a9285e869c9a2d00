"""surfgen.pipelines.export.meshes."""
