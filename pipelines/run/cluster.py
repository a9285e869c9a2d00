"""A Dask executor: chunks of tasks on a Dask cluster, each shape still killable on its worker.

The driver (the process that owns the catalogue) submits *chunks* of consecutive tasks, sized
so that one chunk is about ``target_seconds`` of work (Dask costs milliseconds per task, and a
shape of a rejected draw a few). At most ``2 x`` the cluster's worker threads chunks are in
flight, and never more than ``8 x`` that many chunks past the oldest unfinished one, so the
driver's buffer of out-of-order results stays bounded. Earlier chunks get higher priority.

On a worker, a chunk runs inside a :class:`~surfgen.pipelines.run.executor.KillablePool` of one
process (kept between chunks of the same run): a shape that overruns its timeout or kills its
process comes back as ``timeout``/``crashed``, exactly as with the local executor. The pool's
processes come from a *forkserver*: a Dask worker is a threaded process, and forking one is
not safe. A Dask worker that dies loses only its running chunks; the scheduler runs them again
elsewhere, and the driver takes exactly one result per chunk, so nothing is duplicated.

Results (including the bytes of files) travel back to the driver through Dask.
"""

from __future__ import annotations

import itertools
import logging
import multiprocessing as mp
import threading
import time
import uuid
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from typing import Any

from surfgen.pipelines.run.executor import ExecutorError, KillablePool, TaskResult

log = logging.getLogger(__name__)

INSTALL_HINT = "--executor dask needs Dask: pip install 'surfgen[dask]'"
# Modules the worker-side forkserver imports once, so each shape process starts warm
# (surfgen.pipelines.run.dask_preload also loads the numba kernels and pymeshlab).
PRELOAD = ["surfgen.pipelines.run.sampling", "surfgen.pipelines.run.dask_preload"]


def _load_distributed():
    try:
        import distributed
    except ImportError:
        raise ExecutorError(INSTALL_HINT) from None
    return distributed


class DaskPool:
    """Run ``fn`` (a picklable top-level function or partial) over tasks on a Dask cluster.

    ``scheduler`` is an address (``tcp://host:8786``); without one a ``LocalCluster`` of
    ``workers`` processes on 127.0.0.1 is started and closed with the pool. ``environment``,
    if given, is a picklable function run once in each worker process; its value must equal
    the driver's, or :class:`ExecutorError` is raised (different versions make different shapes).
    Raises :class:`ExecutorError` when Dask is missing or the scheduler cannot be reached.
    """

    def __init__(
        self,
        fn: Callable[[Any], Any],
        timeout: float,
        *,
        scheduler: str | None = None,
        workers: int | None = None,
        environment: Callable[[], Any] | None = None,
        target_seconds: float = 2.0,
        max_chunk: int = 64,
        connect_timeout: float = 20.0,
    ) -> None:
        distributed = _load_distributed()
        # Dask logs every connection and closing at INFO; surfgen's own log level rules.
        logging.getLogger("distributed").setLevel(max(log.getEffectiveLevel(), logging.WARNING))
        self.fn = fn
        self.timeout = timeout
        self.environment = environment
        self.expected = environment() if environment is not None else None
        self.target_seconds = target_seconds
        self.max_chunk = max_chunk
        self.token = uuid.uuid4().hex  # names this run's pools on the workers
        self.cluster = None
        self.lost_chunks = 0  # chunks the scheduler gave up on and the driver resubmitted
        self._threads: tuple[float, int] = (0.0, 1)
        if scheduler:
            try:
                self.client = distributed.Client(scheduler, timeout=connect_timeout)
            except (OSError, TimeoutError, ValueError) as exc:
                raise ExecutorError(
                    f"cannot reach the Dask scheduler at '{scheduler}': {exc} "
                    "(start one with `dask scheduler`, or leave --scheduler out for a local cluster)"
                ) from None
        else:
            import dask

            # Worker processes are daemonic by default, and daemonic processes may not have
            # children: each worker needs its own killable shape process.
            with dask.config.set({"distributed.worker.daemon": False}):
                self.cluster = distributed.LocalCluster(
                    n_workers=workers,
                    threads_per_worker=1,
                    processes=True,
                    host="127.0.0.1",
                    # any free port on loopback: a second cluster (or Jupyter's) has 8787
                    dashboard_address="127.0.0.1:0",
                    silence_logs=logging.ERROR,
                )
            self.client = distributed.Client(self.cluster)
        log.info("dask: %d worker threads at %s", self.threads(), self.client.scheduler.address)

    def threads(self) -> int:
        """Worker threads in the cluster now (refreshed at most once a second)."""
        at, n = self._threads
        if time.monotonic() - at > 1.0:
            n = sum(self.client.nthreads().values())
            self._threads = (time.monotonic(), n)
        return n

    def run(self, tasks: Iterable[Any]) -> Iterator[TaskResult]:
        """One result per task, in completion order; ``tasks`` is pulled a chunk at a time."""
        distributed = _load_distributed()
        it = iter(tasks)
        # Bound to this pool's client: by default as_completed takes the process's default
        # client, whose event loop may be another one (a second Client in the same process),
        # and a future that a killed worker sends back to "pending" then fails to wait
        # ("Event ... is bound to a different event loop"; dask/distributed#4317).
        done = distributed.as_completed(loop=self.client.loop)
        pending: dict[Any, list[Any]] = {}
        window: deque[tuple[Any, list[Any]]] = deque()  # submitted chunks, oldest first
        finished: set[Any] = set()
        chunk, per_task = 2, None
        retries: dict[str, int] = {}
        exhausted = False
        try:
            while True:
                in_flight = max(2, 2 * self.threads())
                while not exhausted and len(pending) < in_flight and len(window) < 4 * in_flight:
                    items = list(itertools.islice(it, chunk))
                    if not items:
                        exhausted = True
                        break
                    fut = self._submit(items)
                    pending[fut] = items
                    window.append((fut, items))
                    done.add(fut)
                if not pending:
                    return
                fut = next(done)
                items = pending.pop(fut)
                try:
                    results, seconds, env = fut.result()
                except distributed.KilledWorker:
                    # The scheduler lost this chunk with several workers in a row: try again,
                    # a few times (each shape is a pure function of its task, so that is safe).
                    n = retries[fut.key] = retries.get(fut.key, 0) + 1
                    if n > 2:
                        raise ExecutorError(
                            f"tasks {items[0]}..{items[-1]} killed {n} Dask workers in a row"
                        ) from None
                    self.lost_chunks += 1
                    again = self._submit(items)
                    retries[again.key] = n
                    pending[again] = items
                    window = deque((again if f is fut else f, i) for f, i in window)
                    done.add(again)
                    continue
                except Exception as exc:  # noqa: BLE001 - the cluster's failures, in one line
                    # Shapes fail inside their pool; what gets here is the worker's setup
                    # (surfgen missing or another version, a forkserver that cannot start...).
                    raise ExecutorError(
                        f"tasks {items[0]}..{items[-1]} failed on the Dask cluster: "
                        f"{type(exc).__name__}: {exc}"
                    ) from exc
                self._check(env)
                finished.add(fut)
                while window and window[0][0] in finished:
                    finished.discard(window.popleft()[0])
                # Size the next chunks to about target_seconds of work.
                rate = seconds / max(len(items), 1)
                per_task = rate if per_task is None else 0.7 * per_task + 0.3 * rate
                chunk = int(min(self.max_chunk, max(1, self.target_seconds / max(per_task, 1e-3))))
                yield from results
        finally:
            if pending:
                self.client.cancel(list(pending))

    def _submit(self, items: list[Any]):
        return self.client.submit(
            run_chunk,
            self.fn,
            self.token,
            self.timeout,
            items,
            self.environment,
            key=f"surfgen-{self.token[:8]}-{items[0]}-{uuid.uuid4().hex[:6]}",
            priority=-_order(items[0]),
            pure=False,
        )

    def _check(self, env: Any) -> None:
        if self.environment is not None and env != self.expected:
            diff = {k: v for k, v in dict(env).items() if dict(self.expected).get(k) != v}
            raise ExecutorError(
                f"a Dask worker runs other versions than the driver ({diff} against "
                f"{ {k: dict(self.expected).get(k) for k in diff} }): install the same surfgen "
                "and dependencies on every machine"
            )

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()

    def __enter__(self) -> DaskPool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _order(task: Any) -> int:
    return task if isinstance(task, int) else 0


# ----------------------------------------------------------------------------- on the worker

_local = threading.local()
_environment: dict[Any, Any] = {}


def run_chunk(
    fn: Callable[[Any], Any],
    token: str,
    timeout: float,
    items: list[Any],
    environment: Callable[[], Any] | None = None,
) -> tuple[list[TaskResult], float, Any]:
    """Run ``items`` through this thread's killable pool (made for run ``token`` on first use).

    Returns the results in task order, the seconds spent and ``environment()``.
    """
    start = time.perf_counter()
    pool = _pool(fn, token, timeout)
    results = sorted(pool.run(items), key=lambda r: items.index(r.task))
    if environment is not None and environment not in _environment:
        _environment[environment] = environment()
    env = _environment.get(environment)
    return results, time.perf_counter() - start, env


def _pool(fn: Callable[[Any], Any], token: str, timeout: float) -> KillablePool:
    current = getattr(_local, "pool", None)
    if current is not None and current[0] == token:
        return current[1]
    if current is not None:
        current[1].close()
    # A Dask worker started by `dask worker` is a daemonic process, which multiprocessing
    # refuses children; its children are ours to manage (the pool kills them when it closes,
    # and they exit when their pipe closes), so the flag is lifted for this process.
    if mp.current_process().daemon:
        mp.current_process()._config["daemon"] = False  # type: ignore[attr-defined]
    ctx = mp.get_context("forkserver")
    ctx.set_forkserver_preload(PRELOAD)
    pool = KillablePool(fn, 1, timeout, context=ctx)
    _local.pool = (token, pool)
    return pool
