"""surfgen.generator.model."""
