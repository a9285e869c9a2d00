"""Parse K3DSurf/MathMod-style formula text into an :class:`~surfgen.generator.expr.Expr` tree.

Grammar (fparser's, as MathMod uses it: ``^`` right-associative and tighter than unary minus)::

    or      := and ("|" and)*
    and     := compare ("&" compare)*
    compare := sum (("=" | "!=" | "<" | "<=" | ">" | ">=") sum)*
    sum     := product (("+" | "-") product)*
    product := unary (("*" | "/" | "%") unary)*
    unary   := ("-" | "+" | "!") unary | power
    power   := atom ("^" unary)?
    atom    := NUMBER | NAME | NAME "(" or ("," or)* ")" | "(" or ")"

Names are ``x y z``, ``pi``, declared parameters, and the functions of
:mod:`surfgen.generator.functions`; ``powf(a,b,c,d, ...)`` (eq. 8) is expanded in place into
``a*x^b*y^c*z^d + ...``. Nothing is ever passed to ``eval``.
"""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from surfgen.generator.errors import FormulaSyntaxError
from surfgen.generator.expr import VARIABLES, Expr, add_all, mul_all, num, walk
from surfgen.generator.functions import FUNCTIONS, MACROS

_TOKEN = re.compile(
    r"\s*(?:(?P<num>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)|(?P<name>[A-Za-z_][A-Za-z_0-9]*)"
    r"|(?P<op><=|>=|!=|[-+*/^(),%<>=!&|]))"
)


@dataclass(frozen=True)
class Token:
    kind: str  # "num", "name", "op", "end"
    text: str
    column: int  # 1-based


def tokenize(text: str) -> list[Token]:
    tokens: list[Token] = []
    pos = 0
    while pos < len(text):
        if text[pos:].strip() == "":
            break
        m = _TOKEN.match(text, pos)
        if m is None or m.end() == pos:
            col = pos + len(text[pos:]) - len(text[pos:].lstrip()) + 1
            raise FormulaSyntaxError(f"unexpected character {text[col - 1]!r}", col)
        kind = m.lastgroup or "op"
        start = m.start(kind)
        tokens.append(Token(kind, m.group(kind), start + 1))
        pos = m.end()
    tokens.append(Token("end", "", len(text) + 1))
    return tokens


class _Parser:
    def __init__(
        self, text: str, params: frozenset[str], functions: Mapping[str, Expr] | None = None
    ) -> None:
        self.text = text
        self.params = params
        self.functions = dict(functions or {})
        self.tokens = tokenize(text)
        self.i = 0
        self.open_parens: list[int] = []

    # -- helpers
    @property
    def tok(self) -> Token:
        return self.tokens[self.i]

    def advance(self) -> Token:
        t = self.tokens[self.i]
        self.i += 1
        return t

    def is_op(self, text: str) -> bool:
        return self.tok.kind == "op" and self.tok.text == text

    def unexpected(self) -> FormulaSyntaxError:
        t = self.tok
        if t.kind == "end":
            if self.open_parens:
                return FormulaSyntaxError(
                    "unbalanced parentheses: '(' is never closed", self.open_parens[-1]
                )
            return FormulaSyntaxError("formula ends too early", t.column)
        if t.text == ")" and not self.open_parens:
            return FormulaSyntaxError("unbalanced parentheses: ')' has no matching '('", t.column)
        return FormulaSyntaxError(f"unexpected {t.text!r}", t.column)

    def expect_close(self) -> None:
        if not self.is_op(")"):
            if self.tok.kind == "end":
                raise self.unexpected()
            raise FormulaSyntaxError(f"expected ')' but found {self.tok.text!r}", self.tok.column)
        self.advance()
        self.open_parens.pop()

    # -- grammar
    def parse(self) -> Expr:
        if self.tok.kind == "end":
            raise FormulaSyntaxError("empty formula", 1)
        tree = self.disjunction()
        if self.tok.kind != "end":
            raise self.unexpected()
        return tree

    def _left_assoc(self, ops: tuple[str, ...], operand) -> Expr:
        left = operand()
        while self.tok.kind == "op" and self.tok.text in ops:
            op = self.advance().text
            left = Expr(op, (left, operand()))
        return left

    def disjunction(self) -> Expr:
        return self._left_assoc(("|",), self.conjunction)

    def conjunction(self) -> Expr:
        return self._left_assoc(("&",), self.comparison)

    def comparison(self) -> Expr:
        return self._left_assoc(("=", "!=", "<", "<=", ">", ">="), self.sum)

    def sum(self) -> Expr:
        left = self.product()
        while self.is_op("+") or self.is_op("-"):
            op = self.advance().text
            left = Expr(op, (left, self.product()))
        return left

    def product(self) -> Expr:
        left = self.unary()
        while self.is_op("*") or self.is_op("/") or self.is_op("%"):
            op = self.advance().text
            left = Expr(op, (left, self.unary()))
        return left

    def unary(self) -> Expr:
        if self.is_op("-"):
            self.advance()
            return Expr("neg", (self.unary(),))
        if self.is_op("+"):
            self.advance()
            return self.unary()
        if self.is_op("!"):
            self.advance()
            return Expr("not", (self.unary(),))
        return self.power()

    def power(self) -> Expr:
        base = self.atom()
        if self.is_op("^"):
            self.advance()
            return Expr("^", (base, self.unary()))
        return base

    def atom(self) -> Expr:
        t = self.tok
        if t.kind == "num":
            self.advance()
            value = float(t.text)
            if not math.isfinite(value):  # e.g. 1e400: a num node must be finite
                raise FormulaSyntaxError(f"number {t.text} is out of range", t.column)
            return num(value)
        if t.kind == "name":
            self.advance()
            if self.is_op("("):
                return self.call(t)
            return self.name(t)
        if self.is_op("("):
            self.open_parens.append(self.advance().column)
            inner = self.disjunction()
            self.expect_close()
            return inner
        raise self.unexpected()

    def name(self, t: Token) -> Expr:
        if t.text in VARIABLES:
            return Expr("var", (), t.text)
        if t.text == "pi":
            return Expr("pi")
        if t.text in self.params:
            return Expr("param", (), t.text)
        if t.text in FUNCTIONS or t.text in MACROS:
            raise FormulaSyntaxError(
                f"function '{t.text}' needs arguments in parentheses", t.column
            )
        allowed = ", ".join([*VARIABLES, "pi", *sorted(self.params)])
        hint = _did_you_mean(t.text, [*VARIABLES, "pi", *self.params])
        raise FormulaSyntaxError(
            f"unknown variable '{t.text}'", t.column, hint or f" (allowed: {allowed})"
        )

    def call(self, t: Token) -> Expr:
        name = t.text
        if name in self.functions:
            self.open_parens.append(self.advance().column)
            args = [] if self.is_op(")") else [self.disjunction()]
            while self.is_op(","):
                self.advance()
                args.append(self.disjunction())
            self.expect_close()
            if len(args) > len(FORMALS):
                raise FormulaSyntaxError(
                    f"{name} takes at most {len(FORMALS)} arguments (x, y, z, t), got {len(args)}",
                    t.column,
                )
            return inline_call(self.functions[name], args)
        if name not in FUNCTIONS and name not in MACROS:
            hint = _did_you_mean(name, [*FUNCTIONS, *MACROS])
            raise FormulaSyntaxError(f"unknown function '{name}'", t.column, hint)
        self.open_parens.append(self.advance().column)
        args = [] if self.is_op(")") else [self.disjunction()]
        while self.is_op(","):
            self.advance()
            args.append(self.disjunction())
        self.expect_close()
        if name == "pow":
            if len(args) != 2:
                raise FormulaSyntaxError(f"pow takes 2 arguments, got {len(args)}", t.column)
            return Expr("^", (args[0], args[1]))
        if name in MACROS:
            return _expand_powf(args, t.column)
        fdef = FUNCTIONS[name]
        n = len(args)
        if n < fdef.min_args or (fdef.max_args is not None and n > fdef.max_args):
            raise FormulaSyntaxError(f"{name} takes {fdef.arity_text()}, got {n}", t.column)
        if name == "fcc" and (n - 1) % 2:
            raise FormulaSyntaxError(
                f"fcc takes x then pairs x1,y1,x2,y2,...: got {n - 1} coordinates", t.column
            )
        if fdef.const_from is not None:
            for k, a in enumerate(args[fdef.const_from :], start=fdef.const_from + 1):
                if not is_constant(a):
                    raise FormulaSyntaxError(
                        f"{name}: argument {k} must be constant (numbers, pi, parameters)",
                        t.column,
                    )
        return Expr(name, tuple(args))


# The formal parameters of a user function (MathMod's Funct): f(x, y, z, t).
FORMALS = (Expr("var", (), "x"), Expr("var", (), "y"), Expr("var", (), "z"), Expr("param", (), "t"))


def inline_call(body: Expr, args: list[Expr]) -> Expr:
    """``body`` with its formals x, y, z, t replaced by ``args`` (missing ones stay as they are)."""
    mapping = dict(zip(FORMALS, args, strict=False))
    memo: dict[Expr, Expr] = {}

    def sub(node: Expr) -> Expr:
        hit = memo.get(node)
        if hit is None:
            hit = mapping.get(node) or (
                Expr(node.op, tuple(sub(a) for a in node.args), node.value) if node.args else node
            )
            memo[node] = hit
        return hit

    return sub(body)


def is_constant(tree: Expr) -> bool:
    """True when the tree uses no variable x, y, z."""
    return all(n.op != "var" for n in walk(tree))


def _expand_powf(args: list[Expr], column: int) -> Expr:
    if not args or len(args) % 4:
        raise FormulaSyntaxError(
            f"powf takes groups of 4 arguments a,b,c,d (one per term), got {len(args)}", column
        )
    x, y, z = (Expr("var", (), v) for v in VARIABLES)
    terms = [
        mul_all([a, Expr("^", (x, b)), Expr("^", (y, c)), Expr("^", (z, d))])
        for a, b, c, d in zip(args[0::4], args[1::4], args[2::4], args[3::4], strict=True)
    ]
    return add_all(terms)


def _did_you_mean(word: str, choices: Iterable[str]) -> str:
    close = difflib.get_close_matches(word.lower(), list(choices), n=1, cutoff=0.6)
    return f" (did you mean {close[0]}?)" if close else ""


def parse(
    text: str, params: Iterable[str] = (), functions: Mapping[str, Expr] | None = None
) -> Expr:
    """Parse ``text`` into a tree; ``params`` are the names allowed as parameters; ``functions``
    are user functions (name -> body in x, y, z and the parameter t), inlined where called.

    Raises :class:`FormulaSyntaxError` naming the column of the problem.
    """
    if not isinstance(text, str):
        raise FormulaSyntaxError(f"formula must be text, got {type(text).__name__}")
    bad = [p for p in params if p in VARIABLES or p == "pi" or p in FUNCTIONS or p in MACROS]
    if bad:
        raise FormulaSyntaxError(f"parameter name '{bad[0]}' is reserved")
    return _Parser(text, frozenset(params), functions).parse()
