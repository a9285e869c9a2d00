"""surfgen.generator.jit."""
