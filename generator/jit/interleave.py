"""Four vectors per iteration for the evaluator's loops: LLVM's interleave count, forced.

Each elementary function's row loop (sin, cos, tan, atan, pow, ...) is one long chain of
dependent operations per element: the reduction, then a polynomial, then the reconstruction,
about a hundred cycles from the argument to the result. LLVM's loop vectoriser gives such a big
loop body one vector per iteration (its cost model interleaves small loops only), so the core
holds about two iterations in flight and waits on latency. With ``-force-vector-interleave=4``
each iteration runs four independent vectors: on the project's Zen 3 the elementary rows ran
1.18-1.26x as fast (median of 12; tan, exp, log, pow, atan2 about 1.3x) and the 50 stored
eq. (13) formulas at 128^3 1.17x (median; 1.21x in total time), the same fields bit for bit
(``benchmarks/interleave.py``; docs/performance/log.md).

It changes no bit: interleaving runs the same operations on more elements at once, and every
operation of the evaluator is elementwise (no reduction, no FMA, no reassociation).

Only the evaluator's compiles get it: a listener of numba's compile events
(:func:`install`) sets LLVM's option while numba compiles a function of the interpreter or of
the elementary functions, with whatever numba compiles on the way, and puts LLVM's default (0:
its cost model decides) back after. numba compiles one function at a time (its global compiler
lock), so nothing else is compiled meanwhile. Other kernels (meshing, filters, the grid
driver's copies) keep LLVM's own choice: their loops are small, or not vectorised, and a bigger
body is only longer to compile (the interpreter's first compile takes about 20 % longer: 75 s
instead of 63 s, two processes side by side).

With the vectorisers off (``SURFGEN_NO_VECTORIZE=1``) LLVM ignores the option.
``SURFGEN_INTERLEAVE=N`` (0 to 16; 0 leaves the choice to LLVM) sets another count, for
measurements: the count is part of numba's cache stamp, so each count compiles its own code.
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Callable, Iterator

log = logging.getLogger(__name__)

DEFAULT_INTERLEAVE = 4
MAX_INTERLEAVE = 16


def interleave_from(environ) -> int:
    """The interleave count: ``SURFGEN_INTERLEAVE`` when it is an integer from 0 (LLVM's own
    choice: the option is never set) to 16, else :data:`DEFAULT_INTERLEAVE` (with a warning
    when it was set to something else)."""
    raw = environ.get("SURFGEN_INTERLEAVE", "").strip()
    if not raw:
        return DEFAULT_INTERLEAVE
    try:
        value = int(raw)
    except ValueError:
        value = -1
    if 0 <= value <= MAX_INTERLEAVE:
        return value
    log.warning(
        "SURFGEN_INTERLEAVE=%r ignored: expected an integer from 0 (LLVM's choice) to %d; using %d",
        raw,
        MAX_INTERLEAVE,
        DEFAULT_INTERLEAVE,
    )
    return DEFAULT_INTERLEAVE


# Vectors per iteration of the evaluator's loops; part of numba's cache stamp (jit/cache.py).
INTERLEAVE = interleave_from(os.environ)

# Functions of these modules hold the evaluator's vector loops.
MODULES = (
    "surfgen.generator.eval.interpreter",
    "surfgen.generator.eval.row_operations",
    "surfgen.generator.elementary",
)


def evaluator_function(module: str | None) -> bool:
    """Whether a function of ``module`` is one of the evaluator's (gets the interleave)."""
    return bool(module) and any(module == m or module.startswith(m + ".") for m in MODULES)


def _set_interleave(count: int) -> None:
    from llvmlite import binding  # deferred: this module imports no numba (module docstring)

    binding.set_option("surfgen", f"-force-vector-interleave={count}")


class _Listener:
    """numba's ``numba:compile`` events: the option is on from the start of the outermost
    compile of an evaluator function to its end (an error included). numba delivers them under
    its global compiler lock, one compile at a time. (Registered as a subclass of numba's
    ``event.Listener`` made in :func:`install`: this module imports no numba, since it is part
    of what runs when numba is imported, see jit/setup.py.)"""

    def __init__(self, setter=_set_interleave) -> None:
        self._set = setter
        self._depth = 0  # evaluator compiles in progress

    def on_start(self, ev) -> None:
        if evaluator_function(_module_of(ev.data)):
            self._depth += 1
            if self._depth == 1:
                self._set(INTERLEAVE)

    @contextlib.contextmanager
    def held(self) -> Iterator[None]:
        """The option on for a compile numba sends no event for (a C function's)."""
        self._depth += 1
        if self._depth == 1:
            self._set(INTERLEAVE)
        try:
            yield
        finally:
            self._depth -= 1
            if self._depth == 0:
                self._set(0)

    def on_end(self, ev) -> None:
        # (an end without its start: the listener was installed in the middle of a compile)
        if self._depth > 0 and evaluator_function(_module_of(ev.data)):
            self._depth -= 1
            if self._depth == 0:
                self._set(0)


def _module_of(data) -> str | None:
    try:
        return data["dispatcher"].py_func.__module__
    except Exception:  # not a dispatcher's compile: not ours
        return None


_INSTALLED: _Listener | None = None


def install() -> None:
    """Register the listener with numba (once per process; jit/setup.py does it when numba is
    imported, before any of surfgen's functions can be defined)."""
    global _INSTALLED
    if _INSTALLED is not None or INTERLEAVE == 0:
        return
    from numba.core import event  # deferred: runs as numba is imported (setup.py)

    _INSTALLED = make_listener()
    event.register("numba:compile", _INSTALLED)


def make_listener(setter: Callable[[int], None] = _set_interleave) -> _Listener:
    """A :class:`_Listener` that numba accepts (a subclass of its ``event.Listener``)."""
    from numba.core import event  # deferred: this module imports no numba

    class _NumbaListener(_Listener, event.Listener):
        pass

    return _NumbaListener(setter)


@contextlib.contextmanager
def evaluator_compile() -> Iterator[None]:
    """Within the block, numba compiles as for the evaluator's functions (four vectors per
    iteration): for the C functions of :mod:`surfgen.generator.eval.row_functions`, whose compiles send
    no ``numba:compile`` event. Nested compiles of dispatchers keep the option on. Holds numba's
    (re-entrant) compiler lock, under which its events arrive too."""
    from numba.core.compiler_lock import global_compiler_lock  # deferred: no numba at import

    if _INSTALLED is None:
        yield
        return
    with global_compiler_lock, _INSTALLED.held():
        yield
