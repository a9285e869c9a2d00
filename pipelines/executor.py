"""Worker processes that can be killed: per-task timeouts and crash isolation.

``concurrent.futures`` breaks the whole pool when one worker dies, and a timer inside a numba
loop fires only when the loop ends; so each worker is a plain process fed through a pipe, and
the parent kills and replaces a worker whose task overruns its deadline or that dies.

An *executor* is anything with ``run(tasks) -> Iterator[TaskResult]`` used as a context manager
(:class:`Executor`): :class:`KillablePool` here, and ``DaskPool`` in
:mod:`surfgen.pipelines.cluster`, which runs chunks of tasks on a Dask cluster with a
``KillablePool`` inside each worker. The sampling run is written once against this interface.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing as mp
import signal
import time
import traceback
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from typing import Any, Protocol

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


def _worker_main(conn: Connection, fn: Callable[[Any], Any]) -> None:
    # Ctrl-C reaches the whole process group: the parent decides, the workers carry on until
    # it kills them (so no worker prints a KeyboardInterrupt traceback of its own).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    while True:
        try:
            task = conn.recv()
        except EOFError:
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
    def __init__(self, ctx, fn: Callable[[Any], Any]) -> None:
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_worker_main, args=(child, fn), daemon=True)
        self.proc.start()
        child.close()
        self.task: Any = None
        self.deadline = 0.0

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
        self.workers = [_Worker(self.ctx, fn) for _ in range(workers)]

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
                        self.workers[i] = _Worker(self.ctx, self.fn)
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
