"""The tape's vocabulary: opcode numbers, operand modes and levels (the tape format:
:class:`surfgen.generator.eval.compiler.Program`).

Opcode numbers are a file format: they are stored with programs and compiled into cached
kernels. Append to :data:`OPCODES`, never renumber.
"""

from __future__ import annotations

# name -> (number, arity). APPEND ONLY: numbers are stored with programs and cached kernels.
OPCODES: dict[str, tuple[int, int]] = {
    "copy": (0, 1),
    "neg": (1, 1),
    "abs": (2, 1),
    "sin": (3, 1),
    "cos": (4, 1),
    "tan": (5, 1),
    "asin": (6, 1),
    "acos": (7, 1),
    "atan": (8, 1),
    "sinh": (9, 1),
    "cosh": (10, 1),
    "tanh": (11, 1),
    "asinh": (12, 1),
    "acosh": (13, 1),
    "atanh": (14, 1),
    "exp": (15, 1),
    "log": (16, 1),
    "log10": (17, 1),
    "sqrt": (18, 1),
    "cbrt": (19, 1),
    "sign": (20, 1),  # numpy's sign: sign(-0) = +0, sign(nan) = nan
    "floor": (21, 1),
    "ceil": (22, 1),
    "square": (23, 1),  # u*u (numpy's pow fast path for exponent 2)
    "recip": (24, 1),  # 1/u (exponent -1, cot = 1/tan, sec, csc)
    "usign": (25, 1),  # constituents.unit_sign: u/|u| with +1 at u = 0
    "powi": (26, 1),  # u^imm (no longer emitted: integer powers are pow with a constant)
    "series": (27, 1),  # the sum of eqs (2)-(4); consts[imm:imm+3] = r, p, exact_loop
    "segsum": (28, 1),  # 0.5 * sum of selector*line (fcc, fcc8); consts[imm] = kind, nseg, rows
    "add": (29, 2),
    "sub": (30, 2),
    "mul": (31, 2),
    "div": (32, 2),
    "pow": (33, 2),  # surfgen's pow with the x^c convention (elementary.power)
    "min": (34, 2),  # np.minimum: NaN propagates, equal operands give the second
    "max": (35, 2),
    "atan2": (36, 2),
    "ratio1": (37, 2),  # a/b with 0/0 read as 1 (rect3)
    # MathMod's comparisons, logic, if and % (logic.py): results 1.0 or 0.0.
    "lt": (38, 2),  # a < b - EPS
    "le": (39, 2),  # a <= b + EPS
    "eq": (40, 2),  # |a - b| <= EPS
    "ne": (41, 2),  # |a - b| > EPS
    "and": (42, 2),
    "or": (43, 2),
    "not": (44, 1),
    "pick": (45, 2),  # b where a is true, else 0 (if's taken branch)
    "pickn": (46, 2),  # 0 where a is true, else b (if's other branch)
    "fmod": (47, 2),  # C fmod (exact)
    "trunc": (48, 1),
    # The paper's round trips in closed form (elementary.roundtrip).
    "atantan": (49, 1),  # atan(tan u)
    "asinsin": (50, 1),  # asin(sin u)
    "acoscos": (51, 1),  # acos(cos u)
    "acotcot": (52, 1),  # acot(cot u) = pi/2 - atan(1/tan u)
    # 1/cos u, 1/sin u, 1/tan u in one row (the bits of the function, then recip): the
    # division overlaps the function's arithmetic instead of a pass of its own (_fuse_reciprocals)
    "sec": (53, 1),
    "csc": (54, 1),
    "cot": (55, 1),
}
OP = {name: num for name, (num, _) in OPCODES.items()}
ARITY = {name: n for name, (_, n) in OPCODES.items()}
OPNAMES = {num: name for name, (num, _) in OPCODES.items()}

# Opcode numbers as globals, for the kernels (numba freezes a global at compile time).
OP_COPY = OP["copy"]
OP_NEG = OP["neg"]
OP_ABS = OP["abs"]
OP_SQRT = OP["sqrt"]
OP_SIGN = OP["sign"]
OP_FLOOR = OP["floor"]
OP_CEIL = OP["ceil"]
OP_SQUARE = OP["square"]
OP_RECIP = OP["recip"]
OP_USIGN = OP["usign"]
OP_POWI = OP["powi"]
OP_ADD = OP["add"]
OP_SUB = OP["sub"]
OP_MUL = OP["mul"]
OP_DIV = OP["div"]
OP_POW = OP["pow"]
OP_MIN = OP["min"]
OP_MAX = OP["max"]
OP_ATAN2 = OP["atan2"]
OP_RATIO1 = OP["ratio1"]
OP_LT = OP["lt"]
OP_LE = OP["le"]
OP_EQ = OP["eq"]
OP_NE = OP["ne"]
OP_AND = OP["and"]
OP_OR = OP["or"]
OP_NOT = OP["not"]
OP_PICK = OP["pick"]
OP_PICKN = OP["pickn"]
OP_FMOD = OP["fmod"]
OP_TRUNC = OP["trunc"]

# Operand modes of a code row.
M_V, M_VV, M_VS, M_SV, M_S = 0, 1, 2, 3, 4
MODE_NAMES = {M_V: "v", M_VV: "vv", M_VS: "vs", M_SV: "sv", M_S: "s"}

# Levels are bit masks of the variables a value depends on.
LEVEL_NAMES = {0: "const", 1: "x", 2: "y", 3: "xy", 4: "z", 5: "xz", 6: "yz", 7: "xyz"}
VAR_BITS = {"x": 1, "y": 2, "z": 4}
# Order in which the blocks run (each reads only blocks before it).
LEVEL_ORDER = (1, 2, 4, 6, 3, 5, 7)
OUT = 7  # store kind of the xyz block: the output field

SEGSUM_FCC, SEGSUM_FCC8 = 0.0, 1.0
SERIES_SAFE = 1e300  # r*(p+1) above this: the series op loops over i like the reference


def run_axis(level: int) -> int:
    """The bit of the axis a block of ``level`` runs along (z innermost)."""
    return 4 if level & 4 else 2 if level & 2 else 1
