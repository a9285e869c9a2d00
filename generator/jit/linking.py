"""Cached kernels loaded without a parsed copy of their code for linking, until one is asked for.

numba stores a cached function as its machine code and the LLVM bitcode of the same functions,
and loads it by parsing that bitcode into a module at once (``CPUCodeLibrary._unserialize``),
kept beside the machine code for as long as the process lives: a later compile that calls the
function links its code in from that module (``_get_module_for_linking``). A process that only
runs cached kernels — every ``surfgen`` command on a warm cache, every sampler worker — never
links them, and holds the parsed modules for nothing: 16.5 of the 190 MiB of a process that
rendered a sculpture (46 kernels, 2.1 MB of bitcode; measured on a 2-core AMD EPYC Zen 2), held
at every moment of the run and so part of its peak.

:func:`install_lazy_linking` wraps the two methods: once numba has loaded a cached library (and
recorded its symbols from the module, as it does), the module is dropped and its bitcode kept
(bytes, an eighth of the parsed size); the first compile that asks to link the library
parses it again (numba's own call, under its compiler lock). Nothing else changes: the machine
code that runs, the symbols numba knows, what a compile links. Installed when numba is first
imported (:mod:`surfgen.generator.jit.setup`); a numba whose libraries do not have these
methods is left as it is.
"""

from __future__ import annotations

import logging
from typing import Any

log = logging.getLogger(__name__)

#: The attribute under which a loaded library keeps its bitcode until it is linked.
KEPT = "_surfgen_linking_bitcode"

_installed = False


def install_lazy_linking() -> bool:
    """Have numba's CPU libraries loaded from the cache parse their linking module on first use
    (the module's docstring). Returns whether the methods are wrapped (once per process)."""
    global _installed
    if _installed:
        return True
    try:  # deferred: jit/setup.py imports this module before numba is imported
        from llvmlite import binding as llvm
        from numba.core import codegen
    except ImportError:  # pragma: no cover (numba requires llvmlite)
        return False
    library = codegen.CPUCodeLibrary
    load = library.__dict__.get("_unserialize")
    link = library.__dict__.get("_get_module_for_linking")
    if not isinstance(load, classmethod) or not callable(link):
        log.debug("this numba's libraries load otherwise: their linking modules left as they are")
        return False
    numba_load = load.__func__

    def _unserialize(cls: type, codegen_: Any, state: tuple) -> Any:
        loaded = numba_load(cls, codegen_, state)
        _, kind, data = state  # numba's (name, kind, data): object code and bitcode
        if kind == "object" and getattr(loaded, "_shared_module", None) is not None:
            loaded._shared_module = None
            setattr(loaded, KEPT, data[1])
        return loaded

    def _get_module_for_linking(self: Any) -> Any:
        bitcode = self.__dict__.pop(KEPT, None)
        if bitcode is not None and self._shared_module is None:
            self._shared_module = llvm.parse_bitcode(bitcode)
        return link(self)

    library._unserialize = classmethod(_unserialize)
    library._get_module_for_linking = _get_module_for_linking
    _installed = True
    return True


def installed() -> bool:
    """Whether :func:`install_lazy_linking` has wrapped numba's methods in this process."""
    return _installed
