"""surfgen.filters: mesh metrics, verdicts, cleanup, remeshing and de-duplication."""

# numba's cache stamp before any jitted function of this package (surfgen/generator/numba_cache.py)
import surfgen.generator  # noqa: F401
