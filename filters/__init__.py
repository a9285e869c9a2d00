"""surfgen.filters: mesh metrics, verdicts, cleanup, remeshing and de-duplication."""
