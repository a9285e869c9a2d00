"""Worker processes that can be killed: per-task timeouts and crash isolation.

``concurrent.futures`` breaks the whole pool when one worker dies, and a timer inside a numba
loop fires only when the loop ends; so each worker is a plain process fed through a pipe, and
the parent kills and replaces a worker whose task overruns its deadline or that dies.

An *executor* is anything with ``run(tasks) -> Iterator[TaskResult]`` used as a context manager
(:class:`Executor`): :class:`KillablePool` here, and ``DaskPool`` in
:mod:`surfgen.pipelines.run.cluster`, which runs chunks of tasks on a Dask cluster with a
``KillablePool`` inside each worker. The sampling run is written once against this interface.
"""

from __future__ import annotations

import contextlib
import ctypes
import gc
import logging
import multiprocessing as mp
import os
import signal
import sys
import time
import traceback
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from typing import Any, Protocol

from surfgen.generator.allocator import keep_freed_memory
from surfgen.generator.errors import SurfgenError

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TaskResult:
    """``status`` is ``ok`` (``value`` holds the result), ``timeout`` or ``crashed``."""

    task: Any
    status: str
    value: Any = None
    message: str = ""


class ExecutorError(SurfgenError):
    """An executor that cannot run: no cluster to connect to, mismatched workers, lost tasks."""


class Executor(Protocol):
    """Runs a function over tasks; every task gets exactly one :class:`TaskResult`."""

    def run(self, tasks: Iterable[Any]) -> Iterator[TaskResult]:
        """Results in any order; ``tasks`` is pulled lazily, so it may stop early."""
        ...

    def __enter__(self) -> Executor: ...

    def __exit__(self, *exc: object) -> None: ...


PARENT_CHECK_SECONDS = 1.0  # how often an idle worker checks that its parent is alive


def _die_with_parent(parent_pid: int) -> None:
    """Ask Linux to SIGKILL this process when its parent dies (``PR_SET_PDEATHSIG``), and
    exit at once if the parent is already gone (it may have died before the call)."""
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        except (OSError, AttributeError):  # pragma: no cover - no prctl: the polling remains
            pass
    if os.getppid() != parent_pid:
        os._exit(1)


def _close_inherited(fds: Iterable[int], keep: int) -> None:
    """Close what a forked worker inherited but must not hold: the other workers' pipe ends
    (else none of them sees end-of-file when the parent dies) and any open SQLite database,
    journal or WAL (the catalogue belongs to the parent)."""
    for fd in fds:
        if fd != keep:
            with contextlib.suppress(OSError):
                os.close(fd)
    with contextlib.suppress(OSError):
        for name in os.listdir("/proc/self/fd"):
            fd = int(name)
            if fd <= 2 or fd == keep:
                continue
            with contextlib.suppress(OSError):
                target = os.readlink(f"/proc/self/fd/{name}")
                if target.endswith(_DATABASE_SUFFIXES) or ".sqlite-" in target:
                    os.close(fd)


_PR_SET_PDEATHSIG = 1
_HELD = {signal.SIGINT, signal.SIGTERM}  # held while a worker is forked
_DATABASE_SUFFIXES = (".sqlite", ".sqlite-wal", ".sqlite-shm", ".sqlite-journal", ".db")


def _worker_main(
    conn: Connection,
    fn: Callable[[Any], Any],
    parent_pid: int | None = None,
    inherited: tuple[int, ...] = (),
) -> None:
    # Ctrl-C reaches the whole process group: the parent decides, the workers carry on until
    # it kills them (so no worker prints a KeyboardInterrupt traceback of its own).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # not the parent's handler: just end
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _HELD)  # blocked by the parent across the fork
    if parent_pid is not None:
        _die_with_parent(parent_pid)
        _close_inherited(inherited, conn.fileno())
        # What the fork inherited (after a cold warm-up, the compiler's 350 000 objects) out of
        # this worker's collections: the first full one wrote to every one of them, copying
        # their pages from the parent (0.63 s, measured; 6 ms frozen).
        gc.freeze()
    keep_freed_memory()
    while True:
        try:
            # Wait in short slices: a worker whose parent is gone (without PR_SET_PDEATHSIG)
            # exits instead of sleeping forever.
            while not conn.poll(PARENT_CHECK_SECONDS):
                if parent_pid is not None and os.getppid() != parent_pid:
                    return
            task = conn.recv()
        except (EOFError, OSError):
            return
        if task is None:
            return
        try:
            conn.send(("ok", task, fn(task), ""))
        except (BrokenPipeError, ConnectionResetError):
            return  # the parent is gone (a closed pool, a Dask worker shut down): no one to answer
        except Exception as exc:  # noqa: BLE001 - the boundary that turns a bug into "crashed"
            log.error("task %r raised:\n%s", task, traceback.format_exc())
            try:
                conn.send(("crashed", task, None, f"{type(exc).__name__}: {exc}"))
            except (BrokenPipeError, ConnectionResetError):
                return


class _Worker:
    def __init__(self, ctx, fn: Callable[[Any], Any], others: Iterable[_Worker] = ()) -> None:
        self.conn, child = ctx.Pipe()
        # Only a forked child inherits the parent's descriptors (forkserver/spawn children don't:
        # there these numbers mean something else).
        forked = ctx.get_start_method() == "fork"
        inherited = tuple(fd for w in others for fd in w.parent_fds()) if forked else ()
        # A forkserver's or spawn's child has another parent than this process (the server):
        # only a forked child can watch this pid.
        parent = os.getpid() if forked else None
        self.proc = ctx.Process(
            target=_worker_main, args=(child, fn, parent, inherited), daemon=True
        )
        # A Ctrl-C during the fork would land in an at-fork handler (logging's), where Python
        # ignores exceptions, and be lost: hold it until the child exists, then deliver it.
        held = signal.pthread_sigmask(signal.SIG_BLOCK, _HELD)
        try:
            self.proc.start()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, held)
        child.close()
        self.task: Any = None
        self.deadline = 0.0

    def parent_fds(self) -> list[int]:
        """The parent's file descriptors for this worker (its pipe end, its process sentinel
        and multiprocessing's liveness pipe): a worker forked later inherits them and closes
        them."""
        fds = []
        with contextlib.suppress(OSError, ValueError):
            fds.append(self.conn.fileno())
        with contextlib.suppress(ValueError, AttributeError):
            fds.append(self.proc.sentinel)
        # multiprocessing keeps (sentinel, liveness pipe) as its finalizer's arguments.
        finalizer = getattr(getattr(self.proc, "_popen", None), "finalizer", None)
        args = getattr(finalizer, "_args", None)
        if isinstance(args, tuple):
            fds += [fd for fd in args if isinstance(fd, int)]
        return fds

    @property
    def busy(self) -> bool:
        return self.task is not None

    def submit(self, task: Any, timeout: float) -> None:
        self.task = task
        self.deadline = time.monotonic() + timeout
        self.conn.send(task)

    def kill(self) -> None:
        if self.proc.is_alive():
            self.proc.kill()
        self.proc.join(timeout=5)
        self.conn.close()


class KillablePool:
    """``workers`` processes running ``fn`` (a picklable top-level function) on tasks."""

    def __init__(
        self, fn: Callable[[Any], Any], workers: int, timeout: float, context: Any = None
    ) -> None:
        methods = mp.get_all_start_methods()
        # fork starts in milliseconds; the parent holds no threads or open catalogue writes then
        # (a threaded parent, such as a Dask worker, passes a forkserver ``context`` instead)
        self.ctx = context or mp.get_context("fork" if "fork" in methods else "spawn")
        self.fn = fn
        self.timeout = timeout
        self.workers: list[_Worker] = []
        for _ in range(workers):
            self.workers.append(_Worker(self.ctx, fn, self.workers))

    def run(self, tasks: Iterable[Any]) -> Iterator[TaskResult]:
        """Results in completion order; pull from ``tasks`` lazily (at most one per worker)."""
        it = iter(tasks)
        exhausted = False
        while True:
            for w in self.workers:
                if not w.busy and not exhausted:
                    try:
                        w.submit(next(it), self.timeout)
                    except StopIteration:
                        exhausted = True
            busy = [w for w in self.workers if w.busy]
            if not busy:
                return
            wait_for = min(w.deadline for w in busy) - time.monotonic()
            ready = wait(
                [w.conn for w in busy] + [w.proc.sentinel for w in busy], timeout=max(0.0, wait_for)
            )
            for i, w in enumerate(self.workers):
                if not w.busy:
                    continue
                result = self._collect(w, ready)
                if result is not None:
                    if result.status != "ok" and not w.proc.is_alive():
                        others = [o for o in self.workers if o is not w]
                        self.workers[i] = _Worker(self.ctx, self.fn, others)
                    yield result

    def _collect(self, w: _Worker, ready: list) -> TaskResult | None:
        task = w.task
        if w.conn in ready:
            try:
                status, _, value, message = w.conn.recv()
            except (EOFError, OSError):  # the pipe closed: the process is gone
                w.kill()
                status, value = "crashed", None
                message = f"worker process died (exit code {w.proc.exitcode})"
            w.task = None  # after a Python exception the worker itself is fine and stays
            return TaskResult(task, status, value, message)
        if w.proc.sentinel in ready or not w.proc.is_alive():
            w.kill()
            w.task = None
            code = w.proc.exitcode
            return TaskResult(task, "crashed", None, f"worker process died (exit code {code})")
        if time.monotonic() >= w.deadline:
            w.kill()
            w.task = None
            return TaskResult(task, "timeout", None, f"took longer than {self.timeout:g} s")
        return None

    def close(self) -> None:
        for w in self.workers:
            if w.proc.is_alive() and not w.busy:
                with contextlib.suppress(OSError):
                    w.conn.send(None)
            w.kill() if w.busy else w.proc.join(timeout=5)
        for w in self.workers:
            if w.proc.is_alive():
                w.kill()

    def __enter__(self) -> KillablePool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
