"""The C allocator's policies (:mod:`surfgen.generator.allocator`), seen through glibc's own
account of its memory (``mallinfo2``) in fresh processes."""

from __future__ import annotations

import ctypes
import subprocess
import sys

import numpy as np
import pytest

from surfgen.generator import allocator
from surfgen.generator.allocator import (
    keep_freed_memory,
    one_shot_memory_policy,
    recycled,
    recycled_many,
    scratch_kept,
)


class _Info(ctypes.Structure):
    """glibc's ``struct mallinfo2``."""

    _fields_ = [
        (name, ctypes.c_size_t)
        for name in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks")
        + ("fsmblks", "uordblks", "fordblks", "keepcost")
    ]


def _mallinfo():
    """glibc's ``mallinfo2`` (in the probes' fresh processes: this module, imported there)."""
    info = ctypes.CDLL(None).mallinfo2
    info.restype = _Info
    return info


def _set_policy(policy: str) -> None:
    """``keep``, ``one_shot`` or ``none`` (glibc's defaults) in this process."""
    if policy == "keep":
        assert keep_freed_memory()
    elif policy == "one_shot":
        assert one_shot_memory_policy()


def heap_probe(policy: str) -> tuple[int, int, int]:
    """In a fresh process under ``policy`` (``keep``, ``one_shot`` or ``none``): the MiB glibc maps
    apart for a 20 MiB array; of eight 16 MiB arrays made then freed, the MiB of them the heap
    still holds as free memory; and the KiB mapped apart for a 1 MiB array made after a 20 MiB
    one was freed (the dynamic threshold would have risen above it)."""
    info = _mallinfo()
    _set_policy(policy)
    start = info()
    block = np.ones(20 << 17)  # 20 MiB of float64
    mapped = (info().hblkhd - start.hblkhd) >> 20
    del block
    blocks = [np.ones(16 << 17) for _ in range(8)]
    alive = info()
    del blocks
    retained = (info().fordblks - alive.fordblks) >> 20
    before = info().hblkhd
    small = np.ones(1 << 17)  # 1 MiB
    small_mapped = (info().hblkhd - before) >> 10
    del small
    return mapped, retained, small_mapped


def scratch_probe(policy: str) -> tuple[int, int, int, int]:
    """In a fresh process under ``policy`` (``one_shot`` or ``none``), within
    ``scratch_kept``: the KiB mapped apart for a 1 MiB array, and the MiB the heap holds free
    once eight 2 MiB arrays are freed; after it: the KiB mapped apart for a 1 MiB array, and
    the MiB the heap still holds free."""
    info = _mallinfo()
    _set_policy(policy)
    with scratch_kept():
        before = info().hblkhd
        small = np.ones(1 << 17)  # 1 MiB
        inside_mapped = (info().hblkhd - before) >> 10
        del small
        blocks = [np.ones(1 << 18) for _ in range(8)]  # 2 MiB each
        alive = info().fordblks
        del blocks
        kept = (info().fordblks - alive) >> 20
    before = info().hblkhd
    small = np.ones(1 << 17)
    after_mapped = (info().hblkhd - before) >> 10
    del small
    return inside_mapped, kept, after_mapped, info().fordblks >> 20


def recycle_probe(policy: str) -> tuple[int, int, int]:
    """In a fresh process under ``policy`` (``one_shot``): the page faults of writing 8 MiB
    and 4 MiB arrays recycled from a 24 MiB one written before, with a 20 MiB array between
    them that does not fit (fresh); then of a fresh 16 MiB array."""
    import resource

    def faults() -> int:
        return resource.getrusage(resource.RUSAGE_SELF).ru_minflt

    _set_policy(policy)
    held = [np.ones(24 << 17)]
    first, too_big, last = recycled_many(
        held, [((1 << 20,), np.float64), ((5 << 20,), np.float32), ((1 << 20,), np.int32)]
    )
    start = faults()
    first.fill(1.0)
    last.fill(2)
    taken = faults() - start
    start = faults()
    too_big.fill(3.0)
    apart = faults() - start
    start = faults()
    np.empty(4 << 20, dtype=np.float32).fill(1.0)
    return taken, apart, faults() - start


def probe(policy: str, name: str = "heap_probe") -> tuple[int, ...]:
    code = f"from tests.generator.test_allocator import {name} as p; print(*p({policy!r}))"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return tuple(int(v) for v in done.stdout.split())


def test_keep_freed_memory_takes_blocks_from_the_heap_and_keeps_them() -> None:
    """A process that called ``keep_freed_memory`` makes a 20 MiB array in its heap, and keeps
    the 128 MiB it frees for the next arrays; a fresh process maps such a block apart, and
    gives the freed heap back beyond glibc's (dynamic) trim threshold."""
    mapped, retained, _ = probe("keep")
    assert mapped == 0 and retained >= 120
    mapped, retained, _ = probe("none")
    assert mapped >= 20 and retained < 120


def test_one_shot_memory_policy_maps_blocks_apart_and_keeps_nothing() -> None:
    """After ``one_shot_memory_policy`` a 1 MiB array is mapped apart even after a 20 MiB one
    was freed (glibc's dynamic threshold, left alone, takes it from the heap then), and the
    freed arrays leave nothing in the heap."""
    mapped, retained, small = probe("one_shot")
    assert mapped >= 20 and retained == 0 and small >= 1024
    _, _, small = probe("none")
    assert small == 0


def test_scratch_kept_reuses_freed_memory_then_gives_it_back() -> None:
    """Under the one-shot policy, ``scratch_kept`` takes a 1 MiB array from the heap and keeps
    what is freed within it for the next ones; after it, such an array is mapped apart again
    and the heap's free memory is given back. Without the policy it changes nothing."""
    inside_mapped, kept, after_mapped, free_after = probe("one_shot", "scratch_probe")
    assert inside_mapped == 0 and kept >= 14
    assert after_mapped >= 1024 and free_after < 2
    inside_mapped, kept, _, _ = probe("none", "scratch_probe")
    assert inside_mapped >= 1024 and kept == 0


def test_recycled_arrays_take_the_pages_of_the_array_done_with() -> None:
    """Under the one-shot policy, arrays recycled from a block written before take its pages
    (12 MiB of them: no fault where fresh ones fault 3072 times); one that does not fit in
    what is left is fresh (its 5120 pages fault), and the block is not grown."""
    taken, apart, fresh = probe("one_shot", "recycle_probe")
    assert taken < 200 and apart >= 5000 and fresh >= 4000


def test_recycled_leaves_arrays_held_elsewhere_alone(monkeypatch) -> None:
    """An array still viewed elsewhere, or not owning its memory (numba's), is left as it is
    and a fresh array made; a view given is replaced by the array it views; outside the
    one-shot policy the array is fresh."""
    from numba import njit

    monkeypatch.setattr(allocator, "_giving_back", True)
    old = np.arange(1000.0)
    view = old[10:20]
    held = [old]
    new = recycled(held, (30,), np.int64)
    assert not held and not np.shares_memory(new, view) and old.size == 1000
    np.testing.assert_array_equal(view, np.arange(10.0, 20.0))
    made_by_numba = njit(lambda n: np.zeros(n))(1000)
    assert not np.shares_memory(recycled([made_by_numba], (30,), np.int64), made_by_numba)
    taken = recycled([np.arange(1000.0)[5:]], (30,), np.int64)
    assert taken.base is not None and taken.base.nbytes == 256  # 30 * 8, to ALIGN bytes
    assert recycled([np.arange(1000.0)], (0, 3), np.int64).shape == (0, 3)
    monkeypatch.setattr(allocator, "_giving_back", False)  # a process keeping freed memory
    assert recycled([np.arange(1000.0)], (30,), np.int64).base is None  # a fresh array


@pytest.mark.parametrize("command", ["render", "export"])
def test_one_shot_commands_give_freed_memory_back(command, monkeypatch, tmp_path) -> None:
    """``render`` and ``export`` set the give-back policy before their work (a stand-in sees
    the call; the command then fails on its missing input, after the call)."""
    from typer.testing import CliRunner

    from surfgen.pipelines.cli import export as export_cli
    from surfgen.pipelines.cli import render as render_cli
    from surfgen.pipelines.cli.main import app

    calls: list[str] = []
    module = render_cli if command == "render" else export_cli
    monkeypatch.setattr(module, "one_shot_memory_policy", lambda: calls.append(command))
    missing = str(tmp_path / "missing")
    args = ["render", "--spec", f"{missing}.json"] if command == "render" else [
        "export", "no-such-key", "-C", missing, "-o", str(tmp_path / "out")]  # fmt: skip
    result = CliRunner().invoke(app, args)
    assert result.exit_code != 0 and calls == [command]


@pytest.mark.parametrize(
    ("setting", "off"),
    [
        ("always defer defer+madvise [madvise] never", True),
        ("[always] defer defer+madvise madvise never", True),
        ("always defer [defer+madvise] madvise never", True),
        ("always [defer] defer+madvise madvise never", False),
        ("always defer defer+madvise madvise [never]", False),
    ],
)
def test_huge_page_advice_is_off_where_faults_would_compact(setting, off, tmp_path, monkeypatch):
    """numpy's huge-page advice goes off exactly where the kernel's defrag setting compacts
    memory on a fault in an advised region; a user's NUMPY_MADVISE_HUGEPAGE is left alone."""
    from surfgen.generator.allocator import (
        no_huge_page_stalls,
        numpy_huge_page_advice,
        thp_defrag,
    )

    monkeypatch.delenv("NUMPY_MADVISE_HUGEPAGE", raising=False)
    path = tmp_path / "defrag"
    path.write_text(setting + "\n")
    assert thp_defrag(path) == setting.split("[")[1].split("]")[0]
    before = numpy_huge_page_advice(True)
    try:
        assert no_huge_page_stalls(path) is off
        assert numpy_huge_page_advice(True) is (not off)  # the advice as the call left it
        monkeypatch.setenv("NUMPY_MADVISE_HUGEPAGE", "1")
        assert no_huge_page_stalls(path) is False and numpy_huge_page_advice(True) is True
    finally:
        numpy_huge_page_advice(before)
    assert thp_defrag(tmp_path / "missing") is None
