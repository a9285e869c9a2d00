"""surfgen.generator.eval."""
