"""The registry of sampler families: named, configurable distributions over eq. (13) instances.

Every family draws a plain :class:`~surfgen.generator.model.equation13.Equation13` — a sum of
products of factors ``A/D * B/E * C/F`` minus d — so every shape stays an instance of the
paper's model; what a family changes is *which* instances are likely (``[sampler] family``,
``mix``). A family is one module with one :class:`~surfgen.generator.model.draw.Family` entry
(its draw function, its settings dataclass read from its ``[sampler.<name>]`` table, a
one-line description, its weight in the default mix), listed once in :data:`BUILT_IN`:

- ``sculpture`` (:mod:`.sculpture`): an envelope carved by an ornament summed over a symmetry
  group;
- ``lattice`` (:mod:`.lattice`): triply periodic patterns cut by the box;
- ``free`` (:mod:`.free`): the first sampler's draw.

Each family is a pure function of ``(seed, index, config)``: it reads only
:func:`~surfgen.generator.model.draw.rng_for` ``(seed, index)``; ``mix`` picks the family from
a second stream of the same index (:func:`surfgen.generator.model.sampler.pick_family`).
Everything that lists families (the ``--family`` help, the config's validation and defaults,
the catalogue's ``family`` field) reads this registry. Another family (a plug-in, a test's) is
added with :func:`register_family` or, for a while, :func:`registered`.

Reading the registry loads no kernel library (``--help`` and ``config show`` read it).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from contextlib import contextmanager

from surfgen.generator.errors import SpecError
from surfgen.generator.model.draw import Family
from surfgen.generator.model.families.assembly import FAMILY as ASSEMBLY
from surfgen.generator.model.families.free import FAMILY as FREE
from surfgen.generator.model.families.infill import FAMILY as INFILL
from surfgen.generator.model.families.lattice import FAMILY as LATTICE
from surfgen.generator.model.families.sculpture import FAMILY as SCULPTURE
from surfgen.generator.model.families.twist import FAMILY as TWIST

MIX = "mix"  # not a family: a weighted pick of one per shape
BUILT_IN: tuple[Family, ...] = (SCULPTURE, LATTICE, INFILL, ASSEMBLY, TWIST, FREE)
_NAME = re.compile(r"[a-z][a-z0-9]*\Z")  # `{name}_{key}` must split at the first "_"
_REGISTRY: dict[str, Family] = {f.name: f for f in BUILT_IN}


def families() -> tuple[Family, ...]:
    """The registered families, built-in ones first, in the order they were registered."""
    return tuple(_REGISTRY.values())


def family_names() -> tuple[str, ...]:
    """The registered families' names: ``('sculpture', 'lattice', 'free', ...)``."""
    return tuple(_REGISTRY)


def family_choices() -> tuple[str, ...]:
    """What ``[sampler] family`` and ``--family`` accept: every family, then ``mix``."""
    return (*_REGISTRY, MIX)


def get_family(name: str) -> Family:
    """The family called ``name``; :class:`SpecError` naming the choices if there is none."""
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise SpecError(f"unknown family {name!r} (allowed: {', '.join(family_names())})") from None


def describe_families() -> str:
    """One line per family, ``name: description``, then ``mix``'s."""
    lines = [f"{f.name}: {f.description}" for f in _REGISTRY.values()]
    return "\n".join([*lines, f"{MIX}: one of the families per shape, drawn with mix_weights"])


def family_list() -> str:
    """The families in words: ``'sculpture, lattice or free'``."""
    return _in_words(family_names())


def family_help() -> str:
    """The help of ``surfgen sample --family``: ``'sculpture, lattice, free or mix (default
    from the config: mix).'``"""
    return f"{_in_words(family_choices())} (default from the config: {MIX})."


def _in_words(names: tuple[str, ...]) -> str:
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} or {names[-1]}"


def default_mix() -> tuple[str, ...]:
    """The default ``mix``: the families with a default weight, in registry order."""
    return tuple(f.name for f in _REGISTRY.values() if f.mix_weight > 0)


def default_mix_weights() -> tuple[float, ...]:
    """The default ``mix_weights``, in the order of :func:`default_mix`."""
    return tuple(f.mix_weight for f in _REGISTRY.values() if f.mix_weight > 0)


def register_family(family: Family) -> None:
    """Add ``family`` to the registry (:class:`SpecError` if its name is taken or unusable:
    lower-case letters and digits, starting with a letter)."""
    if not _NAME.match(family.name) or family.name == MIX:
        raise SpecError(f"a family's name must be lower-case letters and digits: {family.name!r}")
    if family.name in _REGISTRY:
        raise SpecError(f"family {family.name!r} is registered already")
    _REGISTRY[family.name] = family


def unregister_family(name: str) -> None:
    """Remove a family added by :func:`register_family` (built-in ones stay)."""
    if any(f.name == name for f in BUILT_IN):
        raise SpecError(f"family {name!r} is built in")
    _REGISTRY.pop(name, None)


@contextmanager
def registered(family: Family) -> Iterator[Family]:
    """``family`` registered for the ``with`` block (a test's family), removed afterwards."""
    register_family(family)
    try:
        yield family
    finally:
        unregister_family(family.name)
