"""A sculpture's symmetry group: the copies of its ornament (axis permutations, mirrors) and
their sum under an outer power, expanded into eq. (13)'s sum of products (:mod:`.sculpture`)."""

from __future__ import annotations

import itertools
import math
from collections import Counter
from dataclasses import replace

from surfgen.generator.model.equation13 import Factor, PowerFunction, PowerTerm

_CYCLIC = ((0, 1, 2), (1, 2, 0), (2, 0, 1))
_ALL = tuple(itertools.permutations(range(3)))
GROUP_PERMUTATIONS = {
    "none": ((0, 1, 2),),
    "mirror": ((0, 1, 2),),
    "cyclic": _CYCLIC,
    "cyclic_mirror": _CYCLIC,
    "full": _ALL,
    "full_mirror": _ALL,
}


def permute_power(p: PowerFunction, perm: tuple[int, ...], absolute: bool) -> PowerFunction:
    """``p`` with the variable of axis k moved to axis ``perm[k]`` (x -> perm's axis)."""
    terms = []
    for t in p.terms:
        e = [0.0, 0.0, 0.0]
        for k, v in enumerate((t.b, t.c, t.d)):
            e[perm[k]] = v
        terms.append(PowerTerm(t.a, *e))
    return PowerFunction(tuple(terms), p.absolute or absolute)


def permute_factor(f: Factor, perm: tuple[int, ...], absolute: bool = False) -> Factor:
    """The factor with its variables permuted; ``absolute`` puts every power function in
    ``|x|, |y|, |z|`` (the mirror symmetries)."""
    return replace(f, powers=tuple(permute_power(p, perm, absolute) for p in f.powers))


def ornament_combos(copies: int, k: int) -> list[tuple[float, tuple[int, ...]]]:
    """``(Σ_c O_c)^k`` expanded: (multinomial coefficient, copy indices) per product."""
    out = []
    for combo in itertools.combinations_with_replacement(range(copies), k):
        counts = Counter(combo)
        coef = math.factorial(k)
        for c in counts.values():
            coef //= math.factorial(c)
        out.append((float(coef), combo))
    return out


def ornament_terms(
    ornament: Factor, perms: tuple[tuple[int, ...], ...], mirror: bool, k: int
) -> list[tuple[float, tuple[Factor, ...]]]:
    """``(Σ_perms O∘perm)^k`` expanded: (multinomial coefficient, factors) per product."""
    copies = [permute_factor(ornament, p, mirror) for p in perms]
    return [
        (coef, tuple(copies[i] for i in combo)) for coef, combo in ornament_combos(len(copies), k)
    ]
