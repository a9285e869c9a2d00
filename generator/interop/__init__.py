"""surfgen.generator.interop."""
