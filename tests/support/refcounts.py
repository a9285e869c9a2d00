"""Where a numba kernel counts references: its optimised LLVM IR read as a control-flow graph.

numba counts the references to every array it holds with atomic increments and decrements
(``NRT_incref`` / ``NRT_decref``); its pruning pass removes the pairs it can prove redundant,
not those of an array variable reassigned in a loop (an array grown as it fills, two arrays
swapped) or handed to an inlined helper with branches: those stay in the loop, a few atomic
operations per iteration, and took most of the time of the sparse marching's cell loop.
:func:`loop_refcounts` finds them: the calls in the innermost loop around a given call.
"""

from __future__ import annotations

import re

import numba

from surfgen.generator.jit.options import KERNEL

_LABEL = re.compile(r'^("?[A-Za-z0-9_.\-$]+"?):')
_TARGET = re.compile(r'label %("?[A-Za-z0-9_.\-$]+"?)')
_TERMINATORS = ("\n  br ", "\n  switch ", "\n  ret ", "\n  unreachable", "\n  resume ")
REFCOUNTS = ("@NRT_incref", "@NRT_decref")


def kernel_ir(py_func, *args) -> str:
    """The body of ``py_func``'s own function in its optimised LLVM IR, compiled afresh
    (uncached, surfgen's kernel options) for the types of ``args``."""
    kernel = numba.njit(**{**KERNEL, "cache": False})(py_func)
    signature = tuple(numba.typeof(a) for a in args)
    kernel.compile(signature)
    name = kernel.overloads[signature].fndesc.mangled_name
    ir = kernel.inspect_llvm(signature)
    found = re.search(r'define [^\n]*@"?' + re.escape(name) + r'"?\(.*?\n(.*?)\n}\n', ir, re.S)
    assert found, f"no definition of {name} in its module"
    return found.group(1)


def _blocks(body: str) -> tuple[list[str], dict[str, list[str]]]:
    order, blocks, current = ["entry"], {"entry": []}, "entry"
    for line in body.splitlines():
        label = _LABEL.match(line)
        if label:
            current = label.group(1).strip('"')
            if current not in blocks:
                order.append(current)
                blocks[current] = []
            continue
        blocks[current].append(line)
    if not blocks["entry"] and len(order) > 1:  # the body opened with its own label
        order.remove("entry")
    return order, blocks


def _successors(lines: list[str]) -> list[str]:
    text = "\n" + "\n".join(lines)
    end = max(text.rfind(t) for t in _TERMINATORS)
    return [t.strip('"') for t in _TARGET.findall(text[end:])]


def loops(body: str) -> tuple[dict[str, list[str]], list[set[str]]]:
    """The blocks of an LLVM function body (label -> lines) and its natural loops (sets of
    labels, one per loop header: the blocks of all its back edges)."""
    order, blocks = _blocks(body)
    succ = {b: _successors(blocks[b]) for b in order}
    pred: dict[str, list[str]] = {b: [] for b in order}
    for b in order:
        for s in succ[b]:
            pred.setdefault(s, []).append(b)
    every = set(order)
    dom = {b: set(every) for b in order}
    dom[order[0]] = {order[0]}
    changed = True
    while changed:  # dominators, iteratively
        changed = False
        for b in order[1:]:
            known = [dom[p] for p in pred[b] if p in dom]
            new = {b} | (set.intersection(*known) if known else set())
            if new != dom[b]:
                dom[b], changed = new, True
    by_header: dict[str, set[str]] = {}
    for b in order:
        for s in succ[b]:
            if s in dom[b]:  # a back edge b -> s: the loop of header s holds what reaches b
                loop = by_header.setdefault(s, {s})
                todo = [b]
                while todo:
                    n = todo.pop()
                    if n not in loop:
                        loop.add(n)
                        todo.extend(pred.get(n, []))
    return blocks, list(by_header.values())


def refcounts(lines: list[str]) -> int:
    """The reference-counting calls among ``lines``."""
    return sum(line.count(call) for line in lines for call in REFCOUNTS)


def loop_refcounts(body: str, marker: str) -> int:
    """The reference-counting calls in the innermost loop around the first block whose text
    holds ``marker`` (a callee's name); an AssertionError where no loop holds it."""
    blocks, found = loops(body)
    where = next((b for b, lines in blocks.items() if marker in "\n".join(lines)), None)
    assert where is not None, f"no block calls {marker}"
    around = [loop for loop in found if where in loop]
    assert around, f"no loop around the call of {marker}"
    innermost = min(around, key=len)
    return sum(refcounts(blocks[b]) for b in innermost)


def refcounts_in_loops(body: str) -> int:
    """The reference-counting calls in any loop of an LLVM function body."""
    blocks, found = loops(body)
    return sum(refcounts(blocks[b]) for b in set().union(*found)) if found else 0
