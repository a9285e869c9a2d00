"""How large a formula may be: counted as written out (shared sub-trees once per place), checked
before the work, and following what time and memory allow rather than a fixed small number."""

from __future__ import annotations

import pytest

from surfgen.generator.errors import FormulaSyntaxError
from surfgen.generator.formula import limits, parser
from surfgen.generator.formula.expr import Expr, postorder, to_string, tree_size, var
from surfgen.generator.formula.parser import parse


def test_tree_size_counts_shared_subtrees_once_per_place() -> None:
    x = var("x")
    shared = x * x + x  # 5 nodes
    doubled = Expr("+", (shared, shared))
    assert tree_size(shared) == 5 and tree_size(doubled) == 11
    assert len(postorder(doubled)) == 4  # x, x*x, (x*x)+x, the sum: distinct by identity
    tower = x
    for _ in range(200):  # 2^200 nodes written out, 201 distinct ones: counted at once
        tower = Expr("+", (tower, tower))
    assert tree_size(tower) == 2**201 - 1


def test_a_chain_of_functions_is_refused_before_it_is_built(monkeypatch) -> None:
    # each level calls the previous one twice: 2^k terms written out
    monkeypatch.setattr(limits, "MAX_FORMULA_NODES", 20_000)
    built: list[int] = []
    real_inline = parser.inline_call

    def inline(body: Expr, args: list[Expr]) -> Expr:
        out = real_inline(body, args)
        built.append(tree_size(out))
        return out

    monkeypatch.setattr(parser, "inline_call", inline)
    functions = {"f": parse("x^2+y^2+z^2-1")}
    with pytest.raises(FormulaSyntaxError, match="formula too large: .* nodes once written out"):
        for _ in range(40):
            functions["f"] = parse("f(x,y,z,t)+f(y,z,x,t)", ["t"], functions)
    assert 5_000 < tree_size(functions["f"]) <= 20_000  # the last level accepted
    assert max(built) <= 20_000  # nothing over the limit was ever built


def test_memory_is_part_of_the_limit(monkeypatch) -> None:
    monkeypatch.setattr(limits, "available_memory", lambda: 1000 * limits.FORMULA_BYTES_PER_NODE)
    monkeypatch.setattr(limits, "FORMULA_MEMORY_CHECK_FROM", 0)
    limits.check_formula_size(1000)
    with pytest.raises(limits.LimitError, match="1001 nodes need about .* more than the"):
        limits.check_formula_size(1001)


def test_a_formula_beyond_the_old_limits_reads_and_round_trips() -> None:
    # 12,000 terms: 47,999 nodes, over the 20,000 that stopped ordinary MathMod models before
    text = "+".join(f"{k % 7}*x" for k in range(12_000))
    tree = parse(text)
    assert tree_size(tree) == 47_999
    assert parse(to_string(tree)) == tree


def test_small_formulas_do_not_read_the_memory(monkeypatch) -> None:
    def never() -> int:
        raise AssertionError("available_memory read for a small formula")

    monkeypatch.setattr(limits, "available_memory", never)
    parse("x^2+y^2+z^2-1")
    limits.check_formula_size(limits.FORMULA_MEMORY_CHECK_FROM // limits.FORMULA_BYTES_PER_NODE - 1)


def test_the_text_limits_follow_the_node_limit() -> None:
    assert limits.MAX_FORMULA_TOKENS >= 4 * limits.MAX_FORMULA_NODES
    assert limits.MAX_FORMULA_LENGTH >= 24 * limits.MAX_FORMULA_NODES
    assert limits.MAX_SPEC_FILE_BYTES > limits.MAX_FORMULA_LENGTH
