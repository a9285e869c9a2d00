"""surfgen.generator.mesh.mesh."""
