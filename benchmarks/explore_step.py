"""Benchmark: one explore slider step (evaluate + mesh + GLB) against the same step through the CLI.

A slider step in the viewer is ``POST /api/explore`` (the server evaluates the changed spec with
the fast evaluator, extracts the capped surface and encodes a GLB) followed by ``GET`` of the GLB.
This script serves a catalogue on 127.0.0.1 with the real threaded server, takes a typical
catalogued shape (the median face count of the catalogue, 64³), moves its d by 0.5 % per step
and times ``--steps`` round trips over HTTP; the baseline is the same changed spec rendered by
``surfgen render --spec STEP.json --cap -o STEP.glb`` in a new process, as a person without the
viewer would do, timed in the same run.

    python -m benchmarks.explore_step [--catalogue DIR] [--key KEY] [--steps 30] [--cli 5]

Without ``--catalogue`` it samples a small one first (``surfgen sample --n 12 --seed 7``).
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path

from benchmarks import harness
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.catalogue.curation import select_shapes
from surfgen.pipelines.catalogue.store import open_catalogue
from surfgen.pipelines.studies.explore import warm_up
from surfgen.pipelines.studies.knobs import apply_changes
from surfgen.pipelines.web.app import make_server, server_url

SURFGEN = str(Path(sys.executable).parent / "surfgen")  # the venv's console script


def post(url: str, body: dict) -> dict:
    req = urllib.request.Request(
        url, json.dumps(body).encode(), {"Content-Type": "application/json"}
    )
    with urllib.request.urlopen(req, timeout=120) as res:
        return json.loads(res.read())


def get(url: str) -> bytes:
    with urllib.request.urlopen(url, timeout=120) as res:
        return res.read()


def typical_key(root: Path) -> tuple[str, int, float]:
    """The accepted shape with the median face count: key, faces, d."""
    with open_catalogue(root, must_exist=True) as cat:
        shapes = [s for s in select_shapes(cat, sort="faces") if s["d"] is not None]
    s = shapes[len(shapes) // 2]
    return s["key"], s["faces"], s["d"]


def main(argv: list[str] | None = None) -> None:
    ap = harness.parser(__doc__)
    ap.add_argument("--catalogue", type=Path)
    ap.add_argument("--key")
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--cli", type=int, default=5)
    args = ap.parse_args(argv)
    run = harness.Run("explore_step", args)

    tmp = Path(tempfile.mkdtemp(prefix="bench-explore-"))
    root = args.catalogue
    if root is None:
        root = tmp / "cat"
        run.say("sampling a catalogue of 12 shapes (64³) ...")
        subprocess.run(
            [SURFGEN, "sample", "--n", "12", "--seed", "7",
             "--out", str(root), "--no-thumbnails"],
            check=True, capture_output=True,
        )  # fmt: skip
    if args.key:
        with open_catalogue(root, must_exist=True) as cat:
            rec = cat.shape(args.key)
        key, faces, d = rec["key"], rec["faces"], rec["d"]
    else:
        key, faces, d = typical_key(root)
    with open_catalogue(root, must_exist=True) as cat:
        base = cat.spec(key)
    run.say(f"shape {key}: {faces} faces, grid {'x'.join(map(str, base.grid))}, d = {d:g}")

    warm_up()
    server = make_server(root, "127.0.0.1", 0)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    url = server_url(server)
    try:
        post(url + "api/explore", {"key": key, "changes": {}})  # first request: caches, imports
        rounds, server_side, parts = [], [], {"evaluate": [], "mesh": [], "glb": [], "cpu": []}
        step_faces = []
        for i in range(1, args.steps + 1):
            changes = {"d": d * (1 + 0.005 * i)}
            start = time.perf_counter()
            res = post(url + "api/explore", {"key": key, "changes": changes})
            glb = get(url + res["mesh"])
            rounds.append(time.perf_counter() - start)
            server_side.append(res["seconds"])
            for k in parts:
                parts[k].append(res["timings"][k])
            step_faces.append(res["faces"])
            assert glb[:4] == b"glTF"
    finally:
        server.shutdown()
        server.server_close()

    # The same step through the CLI: a spec file and `surfgen render --spec ... --cap -o X.glb`.
    step_spec: SurfaceSpec = apply_changes(base, {"d": d * 1.05})
    spec_file = tmp / "step.json"
    spec_file.write_text(step_spec.to_json())
    cli = []
    for _ in range(args.cli):
        start = time.perf_counter()
        subprocess.run(
            [SURFGEN, "render", "--spec", str(spec_file),
             "--cap", "-o", str(tmp / "step.glb")],
            check=True, capture_output=True,
        )  # fmt: skip
        cli.append(time.perf_counter() - start)

    med = statistics.median(rounds)
    p90 = sorted(rounds)[int(0.9 * (len(rounds) - 1))]
    ms = lambda v: f"{1000 * v:.0f} ms"  # noqa: E731
    run.say(f"slider steps: {len(rounds)}, faces {min(step_faces)}-{max(step_faces)}")
    run.say(
        f"  round trip (POST /api/explore + GET the GLB): median {ms(med)}, p90 {ms(p90)}, "
        f"best {ms(min(rounds))}"
    )
    run.say(
        f"  server evaluate + mesh + GLB: median {ms(statistics.median(server_side))} "
        + "("
        + ", ".join(f"{k} {ms(statistics.median(v))}" for k, v in parts.items() if k != "cpu")
        + ")"
    )
    cpu = statistics.median(parts["cpu"])
    run.say(
        f"  CPU time of the server thread per step (its cost on a quiet core): median {ms(cpu)}"
    )
    run.say(f"  load average after the run: {harness.machine()['load']}")
    run.say(
        f"baseline, the same step through the CLI (new process): median {ms(statistics.median(cli))}"
    )
    run.say(f"ratio CLI / viewer step: {statistics.median(cli) / med:.1f}x")
    run.say(f"target < 150 ms per step: {'met' if med < 0.150 else 'NOT met'} (median round trip)")
    run.record(
        round_trip_seconds=rounds,
        server_seconds=server_side,
        parts=parts,
        cli_seconds=cli,
        cli_over_viewer=statistics.median(cli) / med,
    )
    run.save()


if __name__ == "__main__":
    main()
