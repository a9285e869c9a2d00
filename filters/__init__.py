"""surfgen.filters: mesh metrics, verdicts, cleanup, remeshing and de-duplication."""

# surfgen.generator puts numba's settings (the cache stamp among them) in place for when numba is
# first imported, before any jitted function of this package (surfgen/generator/jit/setup.py)
import surfgen.generator  # noqa: F401
