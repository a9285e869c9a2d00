"""Formula trees: value equality without recursion, and the walks children-first."""

from __future__ import annotations

from surfgen.generator.formula.expr import Expr, num, postorder, var


def test_leaves_compare_by_op_and_value() -> None:
    assert var("x") is var("x")  # one node per variable, shared
    apart = Expr("var", (), "x")  # a leaf built apart (a parser's, an unpickled tree's)
    assert apart == var("x") and apart is not var("x") and hash(apart) == hash(var("x"))
    assert var("x") != var("y")
    assert num(2.0) == num(2.0) and num(2.0) != num(3.0)
    assert num(-0.0) == num(0.0)  # folded at construction
    assert Expr("param", (), "x") != var("x")
    # a leaf against a node of the same op (a function called with no argument)
    assert Expr("sin") != Expr("sin", (var("x"),))
    assert Expr("sin", (var("x"),)) != Expr("sin")
    assert var("x") != "x"


def test_trees_built_apart_are_equal_down_to_their_leaves() -> None:
    a = Expr("+", (Expr("sin", (var("x"),)), num(1.0)))
    b = Expr("+", (Expr("sin", (var("x"),)), num(1.0)))
    c = Expr("+", (Expr("sin", (var("y"),)), num(1.0)))
    assert a == b and hash(a) == hash(b)
    assert a != c
    deep_a, deep_b = var("x"), var("x")
    for _ in range(5000):  # deeper than Python's recursion limit: compared iteratively
        deep_a, deep_b = Expr("neg", (deep_a,)), Expr("neg", (deep_b,))
    assert deep_a == deep_b
    assert Expr("neg", (deep_a,)) != Expr("neg", (Expr("neg", (deep_b,)),))


def test_postorder_by_identity_and_by_value() -> None:
    x1, x2 = Expr("var", (), "x"), Expr("var", (), "x")
    left, right = Expr("sin", (x1,)), Expr("sin", (x2,))
    tree = Expr("+", (left, right))
    by_id = postorder(tree)
    assert [n.op for n in by_id] == ["var", "sin", "var", "sin", "+"]
    assert by_id[0] is x1 and by_id[2] is x2
    by_value = postorder(tree, by_value=True)
    assert [n.op for n in by_value] == ["var", "sin", "+"]  # the copy skipped whole
    assert by_value[1] is left
    shared = Expr("*", (left, left))
    assert [n.op for n in postorder(shared)] == ["var", "sin", "*"]
    for walk in (postorder(tree), postorder(tree, by_value=True)):
        seen: set[int] = set()
        for node in walk:  # children before parents
            assert all(id(a) in seen or a in walk for a in node.args)
            seen.add(id(node))
