"""surfgen.pipelines: sampling runs, the catalogue, curation, export and the CLI."""

# numba's cache stamp before any jitted function of this package (surfgen/generator/numba_cache.py)
import surfgen.generator  # noqa: F401
