"""surfgen.generator.formula."""
