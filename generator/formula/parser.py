"""Parse K3DSurf/MathMod-style formula text into an :class:`~surfgen.generator.formula.expr.Expr` tree.

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
:mod:`surfgen.generator.formula.functions`; ``powf(a,b,c,d, ...)`` (eq. 8) is expanded in place into
``a*x^b*y^c*z^d + ...``. Nothing is ever passed to ``eval``.
"""

from __future__ import annotations

import difflib
import math
import re
import sys
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from surfgen.generator.errors import FormulaSyntaxError
from surfgen.generator.formula.expr import (
    VARIABLES,
    Expr,
    add_all,
    mul_all,
    num,
    postorder,
    printed_nesting,
    tree_size,
)
from surfgen.generator.formula.functions import FUNCTIONS, MACROS
from surfgen.generator.formula.limits import (
    MAX_FORMULA_LENGTH,
    MAX_FORMULA_NESTING,
    MAX_FORMULA_TOKENS,
    check_formula_size,
)

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
    """The tokens of ``text`` (at most :data:`MAX_FORMULA_TOKENS`), then an ``end`` token."""
    tokens: list[Token] = []
    pos = 0
    stop = len(text.rstrip())  # trailing blanks end the formula (computed once: linear time)
    while pos < stop:
        m = _TOKEN.match(text, pos)
        if m is None or m.end() == pos:
            col = pos + len(text[pos:stop]) - len(text[pos:stop].lstrip()) + 1
            raise FormulaSyntaxError(f"unexpected character {text[col - 1]!r}", col)
        kind = m.lastgroup or "op"
        start = m.start(kind)
        tokens.append(Token(kind, m.group(kind), start + 1))
        if len(tokens) > MAX_FORMULA_TOKENS:
            raise FormulaSyntaxError(
                f"formula too long: more than {MAX_FORMULA_TOKENS} numbers, names and operators",
                start + 1,
            )
        pos = m.end()
    tokens.append(Token("end", "", len(text) + 1))
    return tokens


def _short(text: str, limit: int = 40) -> str:
    """``text`` cut for an error message (a 50,000-letter name stays one readable line)."""
    return text if len(text) <= limit else text[: limit - 3] + "..."


class _Parser:
    def __init__(
        self, text: str, params: frozenset[str], functions: Mapping[str, Expr] | None = None
    ) -> None:
        self.text = text
        self.params = params
        self.functions = dict(functions or {})
        self.shapes: dict[str, tuple[int, tuple[int, ...]]] = {}  # see inlined_size
        self.tokens = tokenize(text)
        self.i = 0
        self.open_parens: list[int] = []  # columns of the open '(': also the nesting depth

    def inlined_size(self, name: str, body: Expr, args: list[Expr]) -> int:
        """:func:`tree_size` of ``body`` with its formals replaced by ``args``, without building
        it: the body's size and how often each formal stands in it (once per function)."""
        if name not in self.shapes:
            counts: dict[int, tuple[int, ...]] = {}
            for node in postorder(body):
                hit = FORMALS.index(node) if node in FORMALS else -1
                own = tuple(int(k == hit) for k in range(len(FORMALS)))
                counts[id(node)] = tuple(
                    sum(c) for c in zip(own, *(counts[id(a)] for a in node.args), strict=True)
                )
            self.shapes[name] = (tree_size(body), counts[id(body)])
        size, uses = self.shapes[name]
        return size + sum(n * (tree_size(a) - 1) for n, a in zip(uses, args, strict=False))

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
        return FormulaSyntaxError(f"unexpected {_short(t.text)!r}", t.column)

    def open_paren(self) -> None:
        """Consume '(' and check the nesting limit before the recursion it leads to."""
        column = self.advance().column
        if len(self.open_parens) >= MAX_FORMULA_NESTING:
            raise FormulaSyntaxError(
                f"formula nested too deeply: more than {MAX_FORMULA_NESTING} levels of "
                "parentheses and function calls",
                column,
            )
        self.open_parens.append(column)

    def expect_close(self) -> None:
        if not self.is_op(")"):
            if self.tok.kind == "end":
                raise self.unexpected()
            raise FormulaSyntaxError(
                f"expected ')' but found {_short(self.tok.text)!r}", self.tok.column
            )
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

    def prefixes(self) -> list[str]:
        """Consume a run of unary '+', '-' and '!': the ``neg``/``not`` nodes they make,
        outermost first ('+' makes none). A loop: 10,000 signs are no deeper than one."""
        ops: list[str] = []
        while self.is_op("-") or self.is_op("+") or self.is_op("!"):
            text = self.advance().text
            if text != "+":
                ops.append("neg" if text == "-" else "not")
        return ops

    def unary(self) -> Expr:
        ops = self.prefixes()
        return _apply_prefixes(self.power(), ops)

    def power(self) -> Expr:
        """``atom ("^" prefixes atom)*`` folded from the right (``^`` is right-associative and
        its exponent may carry signs: ``a^-b^c = a^(-(b^c))``); iterative for power towers."""
        atoms = [self.atom()]
        prefixes: list[list[str]] = []
        while self.is_op("^"):
            self.advance()
            prefixes.append(self.prefixes())
            atoms.append(self.atom())
        out = atoms[-1]
        for base, ops in zip(reversed(atoms[:-1]), reversed(prefixes), strict=True):
            out = Expr("^", (base, _apply_prefixes(out, ops)))
        return out

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
            self.open_paren()
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
            f"unknown variable '{_short(t.text)}'", t.column, hint or f" (allowed: {allowed})"
        )

    def call(self, t: Token) -> Expr:
        name = t.text
        if name in self.functions:
            self.open_paren()
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
            body = self.functions[name]
            # the size written out, counted before the inlining builds it
            check_formula_size(self.inlined_size(name, body, args))
            return inline_call(body, args)
        if name not in FUNCTIONS and name not in MACROS:
            hint = _did_you_mean(name, [*FUNCTIONS, *MACROS])
            raise FormulaSyntaxError(f"unknown function '{_short(name)}'", t.column, hint)
        self.open_paren()
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


# Python frames one level of parentheses costs the recursive descent (disjunction ... atom).
FRAMES_PER_NESTING = 12


def _ensure_stack(frames: int) -> None:
    """Make room for ``frames`` more Python frames than the caller already uses: the nesting
    limit bounds the parser's recursion, this makes sure the interpreter allows that much
    (Python 3.11+ recursion between Python functions does not grow the C stack)."""
    depth, frame = 0, sys._getframe()
    while frame is not None:
        depth += 1
        frame = frame.f_back
    needed = depth + frames + 100
    if sys.getrecursionlimit() < needed:
        sys.setrecursionlimit(needed)


def _apply_prefixes(tree: Expr, ops: list[str]) -> Expr:
    """``ops`` (``neg``/``not``, outermost first) applied to ``tree``."""
    for op in reversed(ops):
        tree = Expr(op, (tree,))
    return tree


# The formal parameters of a user function (MathMod's Funct): f(x, y, z, t).
FORMALS = (Expr("var", (), "x"), Expr("var", (), "y"), Expr("var", (), "z"), Expr("param", (), "t"))


def inline_call(body: Expr, args: list[Expr]) -> Expr:
    """``body`` with its formals x, y, z, t replaced by ``args`` (missing ones stay as they are).
    Iterative (children first), so a deep body inlines without recursion."""
    mapping = dict(zip(FORMALS, args, strict=False))
    memo: dict[int, Expr] = {}
    for node in postorder(body):
        hit = mapping.get(node)
        if hit is None:
            hit = (
                Expr(node.op, tuple(memo[id(a)] for a in node.args), node.value)
                if node.args
                else node
            )
        memo[id(node)] = hit
    return memo[id(body)]


def is_constant(tree: Expr) -> bool:
    """True when the tree uses no variable x, y, z."""
    return all(n.op != "var" for n in postorder(tree))


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
    if len(word) > 40:  # no function or variable name is that long
        return ""
    close = difflib.get_close_matches(word.lower(), list(choices), n=1, cutoff=0.6)
    return f" (did you mean {close[0]}?)" if close else ""


def parse(
    text: str, params: Iterable[str] = (), functions: Mapping[str, Expr] | None = None
) -> Expr:
    """Parse ``text`` into a tree; ``params`` are the names allowed as parameters; ``functions``
    are user functions (name -> body in x, y, z and the parameter t), inlined where called.

    Raises :class:`FormulaSyntaxError` naming the column of the problem, also for a formula
    beyond the limits of :mod:`surfgen.generator.formula.limits` (length, tokens, nesting).
    """
    if not isinstance(text, str):
        raise FormulaSyntaxError(f"formula must be text, got {type(text).__name__}")
    if len(text) > MAX_FORMULA_LENGTH:
        raise FormulaSyntaxError(
            f"formula too long: {len(text)} characters (at most {MAX_FORMULA_LENGTH})"
        )
    bad = [p for p in params if p in VARIABLES or p == "pi" or p in FUNCTIONS or p in MACROS]
    if bad:
        raise FormulaSyntaxError(f"parameter name '{bad[0]}' is reserved")
    _ensure_stack(FRAMES_PER_NESTING * MAX_FORMULA_NESTING)
    tree = _Parser(text, frozenset(params), functions).parse()
    check_formula_size(tree_size(tree))  # before anything prints or walks it written out
    if printed_nesting(tree) > MAX_FORMULA_NESTING:
        raise FormulaSyntaxError(
            f"formula nested too deeply: its canonical form needs more than "
            f"{MAX_FORMULA_NESTING} levels of parentheses (e.g. '-(-(-x))', 'x^(-x^(-x))')"
        )
    return tree
