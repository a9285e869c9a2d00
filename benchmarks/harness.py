"""The harness every benchmark shares: options, timing, the machine line, baselines, JSON.

A benchmark is a module run from the checkout's root (``python -m benchmarks.NAME``) whose
``main()`` does::

    args = harness.parser(__doc__, repeats=3, baseline="optional").parse_args(argv)
    run = harness.Run("NAME", args)         # prints the machine line
    timing = harness.best_of(work, args.repeats)
    run.say(f"work {timing.best:.3f} s")
    run.record(work_seconds=timing.best)
    run.save()                              # --json PATH: options, machine and results

- **Timing**: :func:`best_of` (a warm-up call, then the best of N) and :func:`take_turns`
  (several candidates timed in turns, so a busy moment on a shared machine hits them alike).
- **Ratios**: :func:`ratio` is always *baseline time / time now*: above 1, now is faster.
- **Baseline revisions**: :func:`revisions` exports ``--baseline REV`` (``git archive``, so the
  repository's worktrees and branches are not touched) into a temporary folder laid out as an
  importable ``surfgen``; :func:`run_child` runs the same workload there or in this checkout,
  each a fresh ``python -c`` process, and returns the JSON its last line prints.
- **The machine line** (:func:`machine`): CPU model, AVX-512/AVX2, cores, load, versions.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import platform
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from collections.abc import Callable, Hashable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("generator", "filters", "pipelines")  # mapped to surfgen.* by pyproject.toml
Clock = Callable[[], float]
K = TypeVar("K", bound=Hashable)

# ----------------------------------------------------------------------------------- timing


@dataclass(frozen=True)
class Timing:
    """Wall times of the timed calls (seconds, warm-up excluded) and the last call's result."""

    times: tuple[float, ...]
    result: Any = field(default=None, compare=False, repr=False)

    @property
    def best(self) -> float:
        return min(self.times)

    @property
    def median(self) -> float:
        return statistics.median(self.times)


def best_of(
    fn: Callable[[], Any], repeats: int = 5, *, warmup: int = 1, clock: Clock = time.perf_counter
) -> Timing:
    """Call ``fn`` ``warmup`` times untimed, then ``repeats`` times timed (``repeats >= 1``)."""
    if repeats < 1:
        raise ValueError("repeats must be >= 1")
    for _ in range(warmup):
        fn()
    times, result = [], None
    for _ in range(repeats):
        start = clock()
        result = fn()
        times.append(clock() - start)
    return Timing(tuple(times), result)


def take_turns(
    fns: Mapping[K, Callable[[], Any]],
    repeats: int = 5,
    *,
    warmup: int = 0,
    clock: Clock = time.perf_counter,
) -> dict[K, Timing]:
    """Time every candidate once per round, ``repeats`` rounds, the order reversed every other
    round (ABBA): a burst of load then hits all candidates alike."""
    if repeats < 1:
        raise ValueError("repeats must be >= 1")
    for fn in fns.values():
        for _ in range(warmup):
            fn()
    times: dict[K, list[float]] = {name: [] for name in fns}
    results: dict[K, Any] = {}
    for r in range(repeats):
        for name in list(fns) if r % 2 == 0 else list(reversed(fns)):
            start = clock()
            results[name] = fns[name]()
            times[name].append(clock() - start)
    return {name: Timing(tuple(times[name]), results[name]) for name in fns}


def ratio(baseline: float, now: float) -> float:
    """``baseline / now`` for two times: above 1, now is faster."""
    if now <= 0:
        raise ValueError(f"a time must be positive, got {now}")
    return baseline / now


def ratio_summary(before: Sequence[float], after: Sequence[float]) -> str:
    """Per-case time ratios before / after: median, quartiles, and the totals' ratio."""
    b, a = np.asarray(before, dtype=float), np.asarray(after, dtype=float)
    q1, med, q3 = np.percentile(b / a, [25, 50, 75])
    total = ratio(b.sum(), a.sum())
    return f"median {med:.3f}x (quartiles {q1:.3f}x / {q3:.3f}x), total time {total:.3f}x"


# ---------------------------------------------------------------------------------- machine


def _cpuinfo() -> tuple[str, set[str]]:
    """The CPU's model name and flags (/proc/cpuinfo, else lscpu, else platform)."""
    text = ""
    with contextlib.suppress(OSError):
        text = Path("/proc/cpuinfo").read_text()
    if not text:
        with contextlib.suppress(OSError, subprocess.SubprocessError):
            text = subprocess.run(["lscpu"], capture_output=True, text=True, timeout=10).stdout
    model, flags = "", set()
    for line in text.splitlines():
        key, _, value = line.partition(":")
        key = key.strip().lower()
        if key in ("model name", "hardware", "cpu model") and not model:
            model = value.strip()
        elif key in ("flags", "features") and not flags:
            flags = set(value.split())
    return model or platform.processor() or platform.machine() or "unknown CPU", flags


def _version(name: str) -> str:
    try:
        return metadata.version(name)  # not imported: numba alone takes half a second
    except metadata.PackageNotFoundError:
        return "-"


def machine() -> dict[str, Any]:
    """What a figure was measured on: CPU, SIMD level, cores, load, platform and versions."""
    model, flags = _cpuinfo()
    simd = "AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else "no AVX2"
    usable = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return {
        "cpu": model,
        "simd": simd,
        "cores": os.cpu_count() or 1,
        "usable_cores": usable or 1,
        "load": round(os.getloadavg()[0], 2) if hasattr(os, "getloadavg") else None,
        "platform": platform.platform(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numba": _version("numba"),
    }


def machine_line(info: Mapping[str, Any] | None = None) -> str:
    """One line for the top of a benchmark's output."""
    m = machine() if info is None else info
    return (
        f"machine: {m['cpu']} ({m['simd']}), {m['usable_cores']} of {m['cores']} cores, "
        f"load {m['load']}; python {m['python']}, numpy {m['numpy']}, numba {m['numba']}"
    )


# ------------------------------------------------------------------------- options and output


def parser(
    doc: str | None, *, repeats: int | None = None, baseline: str | None = None
) -> argparse.ArgumentParser:
    """The benchmark's parser: its docstring as help, ``--json PATH``, and if asked
    ``--repeats N`` (best of N; ``--repeat`` also accepted) and ``--baseline REV``
    (``baseline="optional"`` or ``"required"``)."""
    text = doc or ""
    ap = argparse.ArgumentParser(
        description=text.strip().split("\n")[0],
        epilog="\n".join(text.strip().split("\n")[1:]),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ap.add_argument("--json", type=Path, metavar="PATH", help="also write the results here")
    if repeats is not None:
        ap.add_argument(
            "--repeats", "--repeat", type=int, default=repeats, help="timed runs (best kept)"
        )
    if baseline is not None:
        if baseline not in ("optional", "required"):
            raise ValueError("baseline is 'optional' or 'required'")
        ap.add_argument(
            "--baseline",
            required=baseline == "required",
            metavar="REV",
            help="git revision to measure in the same run",
        )
    return ap


def _jsonable(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Timing):
        return {"best": value.best, "median": value.median, "times": list(value.times)}
    if isinstance(value, Path):
        return str(value)
    if value is None or isinstance(value, bool | int | float | str):
        return value
    return repr(value)


class Run:
    """One benchmark run: prints the machine line first, collects results, writes JSON."""

    def __init__(self, name: str, args: argparse.Namespace, *, show_machine: bool = True) -> None:
        self.name = name
        self.args = args
        self.machine = machine()
        self.results: dict[str, Any] = {}
        if show_machine:
            self.say(machine_line(self.machine))

    def say(self, text: str = "") -> None:
        """Print a line of the report now (flushed: benchmarks run for minutes)."""
        print(text, flush=True)

    def record(self, **results: Any) -> None:
        """Keep results for the JSON output (arrays, numpy scalars and Timings are converted)."""
        self.results.update(results)

    def payload(self) -> dict[str, Any]:
        options = {k: v for k, v in vars(self.args).items() if k != "json"}
        return _jsonable(
            {
                "benchmark": self.name,
                "machine": self.machine,
                "options": options,
                "results": self.results,
            }
        )

    def save(self) -> dict[str, Any]:
        """Write :meth:`payload` to ``--json PATH`` if given (to a temporary name first)."""
        data = self.payload()
        path = getattr(self.args, "json", None)
        if path is not None:
            write_json(Path(path), data)
        return data


def write_json(path: Path, data: Mapping[str, Any]) -> None:
    """``data`` as indented JSON at ``path``, written to a temporary name and renamed."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=2, allow_nan=True) + "\n")
    os.replace(tmp, path)


# ----------------------------------------------------------------------- baseline revisions


def export_revision(rev: str, into: Path) -> Path:
    """``git archive REV`` unpacked under ``into``, laid out as an importable ``surfgen``;
    returns the folder to put first on ``PYTHONPATH``."""
    tree = into / "tree"
    tree.mkdir(parents=True)
    archive = subprocess.run(
        ["git", "-C", str(ROOT), "archive", rev], check=True, capture_output=True
    ).stdout
    with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
        tar.extractall(tree, filter="data")
    pkg = into / "path" / "surfgen"
    pkg.mkdir(parents=True)
    for name in PACKAGES:
        (pkg / name).symlink_to(tree / name)
    return into / "path"


@contextlib.contextmanager
def revisions(baseline: str | None) -> Iterator[dict[str, Path | None]]:
    """``{"baseline": path, "now": None}`` (``baseline`` exported for the block's duration),
    or ``{"now": None}`` without a baseline; ``None`` stands for this checkout."""
    if baseline is None:
        yield {"now": None}
        return
    with tempfile.TemporaryDirectory(prefix="surfgen-baseline-") as tmp:
        yield {"baseline": export_revision(baseline, Path(tmp)), "now": None}


def child_env(
    path: Path | None = None,
    *,
    with_root: bool = True,
    write_bytecode: bool = False,
    **extra: str,
) -> dict[str, str]:
    """The environment of a child Python: ``path`` (a baseline's) first on ``PYTHONPATH`` so
    its packages shadow the installed ones, then (``with_root``) this checkout's root, for
    ``benchmarks`` and ``tests.support``; ``extra`` variables set. With ``write_bytecode``,
    ``PYTHONDONTWRITEBYTECODE`` is dropped (children cache bytecode as on a user's machine)."""
    env = dict(os.environ, **extra)
    if write_bytecode:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
    paths = [str(path)] if path is not None else []
    paths += [str(ROOT)] if with_root else []
    paths += [env["PYTHONPATH"]] if env.get("PYTHONPATH") else []
    if paths:
        env["PYTHONPATH"] = os.pathsep.join(paths)
    return env


def run_child(
    path: Path | None,
    code: str,
    *args: object,
    env: Mapping[str, str] | None = None,
    check: bool = True,
) -> dict[str, Any]:
    """Run ``python -c code ARGS`` with the code at ``path`` (None: this checkout) in a fresh
    process and return the JSON object its last line prints. If that object has a ``code``
    entry (a module's ``__file__``), it must lie under the expected tree.

    ``env`` extends :func:`child_env`'s. Raises ``subprocess.CalledProcessError`` if the child
    fails and ``check``."""
    done = subprocess.run(
        [sys.executable, "-c", code, *map(str, args)],
        check=check,
        capture_output=True,
        text=True,
        env=child_env(path, **(env or {})),
        cwd=tempfile.gettempdir(),  # not the checkout: `-c` puts the cwd first on sys.path
    )
    if done.returncode != 0:
        return {"returncode": done.returncode, "stderr": done.stderr}
    result = json.loads(done.stdout.strip().splitlines()[-1])
    if isinstance(result, dict) and "code" in result:
        expected = str(path) if path is not None else str(ROOT)
        if not str(result["code"]).startswith(expected):
            raise SystemExit(f"error: ran {result['code']}, expected code under {expected}")
    return result


def timed_child(
    path: Path | None, code: str, *args: object, env: Mapping[str, str] | None = None
) -> tuple[dict[str, Any], float]:
    """:func:`run_child` and the child's wall time, its start and imports included."""
    start = time.perf_counter()
    result = run_child(path, code, *args, env=env)
    return result, time.perf_counter() - start
