"""How long the commands that compute nothing take, against a baseline revision: ``--help``,
``presets``, ``config show``, ``catalogue list``, ``catalogue show``, ``catalogue star``, each a
fresh process.

    python -m benchmarks.cli_start --baseline REV [--runs 10] [--json PATH]

Both trees run the same commands on the same small catalogue (made first by this tree's
``surfgen sample``), taking turns in ABBA order; each command is run once untimed per tree first,
so that both have their bytecode cached (``PYTHONDONTWRITEBYTECODE`` is unset for the children,
as on a user's machine). Prints the median wall time of each command for both trees and the
ratio baseline / this tree (above 1: this tree starts faster), and which of the kernel libraries
(numba, trimesh, pymeshlab, scipy, ...) each tree's process loaded.
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks import harness

HEAVY = ("numba", "llvmlite", "scipy", "trimesh", "pymeshlab", "skimage", "networkx")

_CLI = f"""
import json, sys
from surfgen.pipelines.cli.main import main
code = main(sys.argv[1:])
print(json.dumps(sorted(m for m in {HEAVY!r} if m in sys.modules)), file=sys.stderr)
sys.exit(code)
"""


def run_cli(path: Path | None, args: list[str]) -> tuple[float, list[str]]:
    """Wall time of ``surfgen ARGS`` in a fresh process, and the kernel libraries it loaded."""
    t0 = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-c", _CLI, *args],
        env=harness.child_env(path, with_root=False, write_bytecode=True),
        capture_output=True,
        text=True,
    )
    seconds = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"surfgen {' '.join(args)} failed:\n{done.stderr}")
    return seconds, json.loads(done.stderr.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    ap = harness.parser(__doc__, baseline="required")
    ap.add_argument("--runs", type=int, default=10, help="timed runs per command and tree")
    args = ap.parse_args(argv)
    run = harness.Run("cli_start", args)

    with (
        harness.revisions(args.baseline) as trees,
        tempfile.TemporaryDirectory(prefix="bench-cli-start-") as tmp,
    ):
        cat = Path(tmp) / "cat"
        run_cli(None, ["sample", "--n", "3", "--seed", "1", "--grid", "24", "--out", str(cat)])
        key = run_cli_output(["catalogue", "list", "-C", str(cat), "--json"])[0]["key"]
        commands = {
            "--help": ["--help"],
            "presets": ["presets"],
            "config show": ["config", "show"],
            "catalogue list": ["catalogue", "list", "-C", str(cat)],
            "catalogue show": ["catalogue", "show", "-C", str(cat), key],
            "catalogue star": ["catalogue", "star", "-C", str(cat), key, "4"],
        }
        run.say(f"baseline {args.baseline} against this tree, {args.runs} runs each (ABBA)")
        run.say(f"{'command':<16} {'baseline':>9} {'now':>9} {'ratio':>7}  loaded (baseline | now)")
        for name, cli_args in commands.items():
            loaded = {tree: run_cli(path, cli_args)[1] for tree, path in trees.items()}
            times: dict[str, list[float]] = {tree: [] for tree in trees}
            for i in range(args.runs):
                order = list(trees) if i % 4 in (0, 3) else list(reversed(trees))
                for tree in order:
                    times[tree].append(run_cli(trees[tree], cli_args)[0])
            base, now = (statistics.median(times[t]) for t in ("baseline", "now"))
            run.say(
                f"{name:<16} {base:>8.3f}s {now:>8.3f}s {harness.ratio(base, now):>6.2f}x  "
                f"{','.join(loaded['baseline']) or '-'} | {','.join(loaded['now']) or '-'}"
            )
            run.record(
                **{name: {"median_seconds": {"baseline": base, "now": now}, "loaded": loaded}}
            )
    run.save()
    return 0


def run_cli_output(args: list[str]) -> object:
    """The JSON that this tree's ``surfgen ARGS`` prints."""
    done = subprocess.run(
        [sys.executable, "-c", _CLI, *args],
        env=harness.child_env(None, with_root=False, write_bytecode=True),
        capture_output=True,
        text=True,
    )
    return json.loads(done.stdout)


if __name__ == "__main__":
    raise SystemExit(main())
