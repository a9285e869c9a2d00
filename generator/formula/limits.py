"""The documented limits of surfgen's inputs, in one place (docs/reference/errors.md).

Every boundary checks its limit *before* the work that the limit protects (recursion, allocation,
reading), so a hostile or careless input ends in one :class:`~surfgen.generator.errors.SurfgenError`
line instead of a ``RecursionError``, ``MemoryError`` or a stalled machine.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from surfgen.generator.errors import FormulaSyntaxError, SpecError, SurfgenError

# Formulas: the tree, written out, has at most MAX_FORMULA_NODES nodes, and neither the text nor
# its canonical form nests parentheses (grouping and function calls) deeper than
# MAX_FORMULA_NESTING. Nothing that walks a tree recurses (parser, printer, compiler), so the
# node limit follows what time and memory allow: reading a formula (parsing with MathMod's
# ``Funct``s inlined, printing it, parsing the printed form back) and compiling it cost about
# 0.1 ms and 0.5 KB per node on this project's 2-core machine (measured on MathMod models of
# 28,000 and 120,000 nodes), so the largest formula takes about a minute and 250 MB before it is
# evaluated. The size is counted before that work: a chain of inlined functions whose written
# form would be too large is refused as soon as its definition is read (counting shares
# sub-trees, so it costs nothing). The text limits follow from the node limit so that the
# canonical form of any accepted tree is itself accepted (parse(print(t)) == t): at most 4
# tokens and 24 characters (the longest number) per node.
MAX_FORMULA_NODES = 500_000
FORMULA_BYTES_PER_NODE = 1024  # the 0.5 KB measured, doubled for the compiler's tables
FORMULA_MEMORY_CHECK_FROM = 64 << 20  # formulas needing less are not checked against memory
MAX_FORMULA_NESTING = 64
MAX_FORMULA_TOKENS = 4 * MAX_FORMULA_NODES
MAX_FORMULA_LENGTH = 24 * MAX_FORMULA_NODES

# ``--where`` expressions: characters, conditions and nesting (parentheses).
MAX_WHERE_LENGTH = 4_000
MAX_WHERE_CONDITIONS = 200
MAX_WHERE_NESTING = 50

# Stars a curator may give a shape.
MAX_STARS = 5

# Input files read whole into memory.
MAX_SPEC_FILE_BYTES = MAX_FORMULA_LENGTH + (1 << 20)  # a spec (or export sidecar) JSON
MAX_CONFIG_FILE_BYTES = 1 << 20  # a config TOML: 1 MiB
MAX_JSON_DEPTH = 32  # nesting of JSON arrays/objects in a spec file or a web request

# Seeds: what numpy's SeedSequence and SQLite's INTEGER both hold.
MAX_SEED = 2**63 - 1
# Counts given on the command line (--n, --max-draws, --limit, ...): SQLite's INTEGER.
MAX_COUNT = 2**63 - 1


class LimitError(SurfgenError):
    """An input beyond one of the documented limits (size, depth, memory, range)."""


class FormulaSizeError(LimitError, FormulaSyntaxError):
    """A formula beyond the size its reading and compiling can afford."""


def read_bounded(path: str | os.PathLike, limit: int, what: str) -> bytes:
    """The bytes of ``path``, refusing a file (or device, or pipe) longer than ``limit``.

    Reads at most ``limit + 1`` bytes, so ``/dev/zero`` or a 5 GB file costs nothing.
    Raises :class:`LimitError` when too long, ``OSError`` when it cannot be read.
    """
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(21, "Is a directory", str(path))
    with open(path, "rb") as f:
        data = f.read(limit + 1)
    if len(data) > limit:
        raise LimitError(f"{what} {path} is larger than {format_bytes(limit)} (the limit)")
    return data


def decode_text(data: bytes, path: str | os.PathLike, what: str) -> str:
    """UTF-8 text of a file's bytes; :class:`LimitError` naming the byte offset otherwise."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise LimitError(
            f"{what} {path} is not UTF-8 text (bad byte 0x{data[exc.start]:02x} at offset {exc.start})"
        ) from None
    if "\x00" in text:
        raise LimitError(f"{what} {path} is not text (it holds NUL bytes)")
    return text


def read_text_file(path: str | os.PathLike, limit: int, what: str) -> str:
    """UTF-8 text of a small input file, read without trusting its size (``/dev/zero``).
    Raises :class:`SpecError` (or :class:`LimitError`) naming the file and the problem."""
    try:
        data = read_bounded(path, limit, what)
    except OSError as exc:
        raise SpecError(f"cannot read {what} {path}: {exc.strerror}") from None
    return decode_text(data, path, what)


def json_depth_ok(text: str, limit: int = MAX_JSON_DEPTH) -> bool:
    """True when the JSON text nests arrays/objects at most ``limit`` deep (checked before
    ``json.loads``, which recurses). Brackets inside strings are skipped."""
    depth = 0
    in_string = escaped = False
    for ch in text:
        if in_string:
            if escaped:
                escaped = False
            elif ch == "\\":
                escaped = True
            elif ch == '"':
                in_string = False
        elif ch == '"':
            in_string = True
        elif ch in "[{":
            depth += 1
            if depth > limit:
                return False
        elif ch in "]}":
            depth -= 1
    return True


def format_bytes(n: float) -> str:
    """``1536`` → ``'1.5 KiB'``."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if abs(n) < 1024 or unit == "TiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} TiB"  # pragma: no cover


def check_seed(seed: int, option: str = "--seed") -> int:
    """``seed`` if it is a whole number in [0, 2^63 - 1]; :class:`LimitError` otherwise."""
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise LimitError(f"{option} must be a whole number from 0 to 2^63-1, got {seed}")
    return seed


def check_count(value: int, option: str, low: int = 1, high: int = MAX_COUNT) -> int:
    """``value`` if it is a whole number in [low, high]; :class:`LimitError` otherwise."""
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        top = "2^63-1" if high == MAX_COUNT else str(high)
        raise LimitError(f"{option} must be a whole number from {low} to {top}, got {value}")
    return value


# ----------------------------------------------------------------------------- memory

# Bytes per grid point, measured on this project's machine (tracemalloc peaks of `render` on
# 128^3 and 192^3 grids): the float64 field is 8; marching cubes' working arrays (float32
# offsets, the capped copy, the mixed cells' list: 40 bytes a cell, about 20 a face) about 20;
# the mesh about 120 bytes per face, with a typical surface giving 0.1-0.25 faces per point
# (noise up to 1.2: the estimate is for a typical shape, and an out-of-memory error is still
# reported in one line).
FIELD_BYTES_PER_POINT = 8
MARCHING_BYTES_PER_POINT = 20
MESH_BYTES_PER_POINT = 30
CLEANUP_MESH_COPIES = 4  # pymeshlab's cleanup and remeshing hold a few copies of the mesh

# The sparse path (surfgen.generator.eval.sparse) holds only the blocks the surface may cross,
# so its memory grows with the surface, about N^2 for an N^3 grid.  Per N^2 (measured with
# benchmarks/bench_sparse.py, RSS peaks at 256-1024 on the presets and sampled sculptures, the
# largest ratio found, rounded up): sampled points (their values, float32 offsets, inside flags,
# duplicated on shared block faces) and the mesh with marching cubes' lists.
SPARSE_POINTS_PER_AREA = 96
SPARSE_BYTES_PER_SAMPLE = 24
SPARSE_MESH_BYTES_PER_AREA = 3000
# What meshing adds per cell to mesh, from the list of those cells to the mesh with its walls
# classified and written to a file in memory (``surfgen render``), checked by a sparse run once
# it has counted its cells (:class:`MemoryBudget`): 216-285 bytes measured on equations B and
# C, a sculpture and a lattice at 256-512^3 (the log, 2026-12-06 (16)), with room for surfaces
# of more faces a cell.
SPARSE_BYTES_PER_MIXED_CELL = 400


def estimate_memory(
    points: int,
    mesh: bool = True,
    field_copy: bool = False,
    cleanup: bool = False,
    sparse: bool = False,
) -> dict[str, int]:
    """The memory a command needs for a grid of ``points`` samples, by part (bytes).

    ``mesh``: marching cubes and a mesh are made; ``field_copy``: the field is also encoded
    as a file in memory; ``cleanup``: the mesh goes through the export cleanup chain;
    ``sparse``: the sparse path (only the blocks the surface may cross: parts that grow with
    ``points ** (2/3)``, a surface's size)."""
    if sparse:
        area = round(points ** (2 / 3))
        sampled = min(points * 1.5, SPARSE_POINTS_PER_AREA * area)
        parts = {"sparse field": int(SPARSE_BYTES_PER_SAMPLE * sampled)}
        if mesh:
            copies = CLEANUP_MESH_COPIES if cleanup else 1
            parts["mesh"] = min(
                SPARSE_MESH_BYTES_PER_AREA * area * copies,
                (MARCHING_BYTES_PER_POINT + MESH_BYTES_PER_POINT * copies) * points,
            )
        return parts
    parts = {"field": FIELD_BYTES_PER_POINT * points}
    if field_copy:
        parts["field file"] = FIELD_BYTES_PER_POINT * points
    if mesh:
        parts["marching cubes"] = MARCHING_BYTES_PER_POINT * points
        copies = CLEANUP_MESH_COPIES if cleanup else 1
        parts["mesh"] = MESH_BYTES_PER_POINT * points * copies
    return parts


def available_memory() -> int:
    """The machine's available memory (``MemAvailable``), or its physical memory elsewhere."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError):  # pragma: no cover - not POSIX
        return 1 << 34


def resident_memory() -> int:
    """This process's resident memory in bytes (``/proc/self/statm``; 0 where it is missing)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


@dataclass(frozen=True)
class MemoryBudget:
    """What a command may add to its process's memory, checked again as the work learns its
    size. The estimate before a run (:func:`estimate_memory`) assumes a typical surface; a
    sparse run learns how many leaves it samples, bricks it keeps and cells it meshes, and
    :meth:`check` refuses the next step before it allocates (equation B's foam crosses every
    leaf: at 1024^3 its sparse render was killed by the kernel's out-of-memory killer, past the
    estimate's 5.2 GiB). ``limit``: bytes the command may add; ``start``: the process's
    resident memory when the command began; ``what`` names the command in the message;
    ``copies``: the copies of a finished mesh the command goes on to hold (export's cleanup
    and remeshing: :data:`CLEANUP_MESH_COPIES`)."""

    limit: int
    what: str
    source: str
    start: int
    copies: int = 1

    @classmethod
    def begin(
        cls, limit: int | None, what: str, copies: int = 1, setting: str | None = "--max-memory"
    ) -> MemoryBudget:
        """A budget from now on: ``limit`` bytes (None: the memory available now); ``setting``
        names the option that sets the limit in the message (None: there is none)."""
        source = _limit_source(limit, setting)
        have = available_memory() if limit is None else int(limit)
        return cls(have, what, source, resident_memory(), copies)

    @classmethod
    def after_estimate(
        cls,
        parts: dict[str, int],
        limit: int | None,
        what: str,
        copies: int = 1,
        setting: str | None = "--max-memory",
    ) -> MemoryBudget:
        """Refuse the command where its estimate ``parts`` exceeds the limit
        (:func:`check_memory`, before anything is allocated), else its budget from now on
        (:meth:`begin`): the two checks of a command that meshes one grid."""
        check_memory(parts, limit, what, setting=setting)
        return cls.begin(limit, what, copies, setting)

    def mesh_bytes(self, cells: int) -> int:
        """What meshing ``cells`` crossed cells adds, and what the command then does with the
        mesh (:data:`SPARSE_BYTES_PER_MIXED_CELL` a cell and copy)."""
        return int(cells) * SPARSE_BYTES_PER_MIXED_CELL * self.copies

    def in_use(self) -> int:
        """What the command holds beyond the process's memory when it began."""
        return max(resident_memory() - self.start, 0)

    def check(self, need: int, step: str) -> None:
        """Refuse ``step`` when its ``need`` (bytes, beyond what the command holds) would take
        the command past its limit: :class:`LimitError`, before ``step`` allocates."""
        used = self.in_use()
        if used + need > self.limit:
            raise LimitError(
                f"{self.what}: {step} needs about {format_bytes(need)} more beside the "
                f"{format_bytes(used)} in use, more than the limit of {format_bytes(self.limit)} "
                f"({self.source}); use a smaller grid"
            )


def check_step(budget: MemoryBudget | None, need: int, step: str) -> None:
    """:meth:`MemoryBudget.check` where there is a budget (callers without one, the sampler and
    the Python API's small grids, check nothing)."""
    if budget is not None:
        budget.check(need, step)


_UNITS = {"": 1, "b": 1, "k": 1 << 10, "m": 1 << 20, "g": 1 << 30, "t": 1 << 40}


def parse_size(text: str, option: str = "--max-memory") -> int:
    """``'4G'``, ``'512MiB'``, ``'1.5g'``, ``'1000000'`` → bytes (binary units).
    Raises :class:`LimitError`."""
    raw = str(text).strip().lower().replace(" ", "")
    body = raw[:-2] if raw.endswith("ib") else raw[:-1] if raw.endswith("b") else raw
    unit = body[-1:] if body[-1:] in _UNITS and body[-1:] != "" and not body[-1:].isdigit() else ""
    number = body[: len(body) - len(unit)]
    try:
        value = float(number)
    except ValueError:
        value = float("nan")
    if not (value > 0 and value * _UNITS[unit] < 2**62):
        raise LimitError(
            f"{option} must be a positive size such as 512M, 4G or 1.5GiB, got '{text}'"
        )
    return int(value * _UNITS[unit])


def check_formula_size(nodes: int) -> None:
    """Refuse a formula of ``nodes`` nodes (written out) beyond :data:`MAX_FORMULA_NODES` or
    beyond what the available memory holds, before it is printed, parsed back or compiled.
    Raises :class:`FormulaSizeError` (a :class:`LimitError`)."""
    if nodes > MAX_FORMULA_NODES:
        raise FormulaSizeError(
            f"formula too large: {nodes} nodes once written out (at most {MAX_FORMULA_NODES})"
        )
    need = nodes * FORMULA_BYTES_PER_NODE
    if need < FORMULA_MEMORY_CHECK_FROM:  # every parse passes here: no /proc read for small ones
        return
    have = available_memory()
    if need > have:
        raise FormulaSizeError(
            f"formula too large: {nodes} nodes need about {format_bytes(need)} of memory, more "
            f"than the {format_bytes(have)} available"
        )


def _limit_source(limit: int | None, setting: str | None) -> str:
    """What set a memory limit, for a message: ``--max-memory sets it``, or the available
    memory (and the option that would set it)."""
    if limit is not None:
        return f"{setting} sets it" if setting else "the limit given"
    return f"the available memory; {setting} sets it" if setting else "the available memory"


def check_memory(
    parts: dict[str, int],
    limit: int | None,
    what: str,
    times: int = 1,
    setting: str | None = "--max-memory",
) -> int:
    """Refuse, before anything is allocated, a command whose estimate exceeds ``limit`` (None:
    the machine's available memory). ``times`` parallel copies (worker processes); ``setting``:
    the option that sets the limit, named in the message (None: there is none).
    Returns the estimate; raises :class:`LimitError` with the estimate, its parts and the limit."""
    need = sum(parts.values()) * times
    source = _limit_source(limit, setting)
    limit = available_memory() if limit is None else limit
    if need > limit:
        detail = ", ".join(f"{k} {format_bytes(v)}" for k, v in parts.items())
        per = f" x {times} workers" if times > 1 else ""
        raise LimitError(
            f"{what} needs about {format_bytes(need)} of memory ({detail}{per}), more than the "
            f"limit of {format_bytes(limit)} ({source}); use a smaller grid"
        )
    return need
