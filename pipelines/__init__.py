"""surfgen.pipelines: sampling runs, the catalogue, curation, export and the CLI."""

# surfgen.generator puts numba's settings (the cache stamp among them) in place for when numba is
# first imported, before any jitted function of this package (surfgen/generator/numba_setup.py)
import surfgen.generator  # noqa: F401
