"""``benchmarks/main_job.py``: warm runs share the code's numba cache, ``--cold`` ones each get an
empty cache of their own and are timed from the child's start."""

from __future__ import annotations

import os
from types import SimpleNamespace

from benchmarks import main_job


def test_cold_runs_each_get_an_empty_cache_of_their_own(monkeypatch):
    seen = []

    def child(path, code, *args, env=None):
        cache = (env or {}).get("NUMBA_CACHE_DIR")
        seen.append((args[-1], cache, cache is not None and os.listdir(cache) == []))
        return {}

    monkeypatch.setattr(main_job.harness, "run_child", child)
    args = SimpleNamespace(n=3, seed=7, workers=2, cold=True)
    main_job._run(None, args)
    main_job._run(None, args)
    assert [(mode, empty) for mode, _, empty in seen] == [("cold", True), ("cold", True)]
    assert seen[0][1] != seen[1][1] and not any(os.path.exists(c) for _, c, _ in seen)
    seen.clear()
    main_job._run(None, SimpleNamespace(n=3, seed=7, workers=2, cold=False))
    assert seen == [("warm", None, False)]  # the code's own cache, warmed untimed by the child


def test_a_cold_child_skips_the_untimed_warm_up(monkeypatch, capsys):
    # the child's own code, with the sampler's run replaced: a warm child first samples one
    # shape untimed (loading every kernel), a cold one times the job alone from its start
    import json
    import sys

    import surfgen.pipelines.run.sampling as sampling

    calls = []

    def run_sample(n, seed, config, catalogue, workers):
        calls.append(n)
        return SimpleNamespace(accepted=n, drawn=n, counts={})

    monkeypatch.setattr(sampling, "run_sample", run_sample)
    for mode, expected in (("warm", [1, 3]), ("cold", [3])):
        calls.clear()
        monkeypatch.setattr(sys, "argv", ["-c", "3", "7", "2", mode])
        exec(compile(main_job._CHILD, "<child>", "exec"), {})
        out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
        assert calls == expected and out["accepted"] == 3 and out["wall"] >= 0
