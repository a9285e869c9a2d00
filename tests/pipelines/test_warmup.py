"""The driver's warm-up runs every numba kernel a sampled shape needs, so forked workers never
compile one inside a shape's timeout."""

from __future__ import annotations

import json
import subprocess
import sys

# In a fresh process: in this one, earlier tests may have compiled what the warm-up forgets.
CHECK = """
import json, sys, tempfile
from pathlib import Path
from numba.core.registry import CPUDispatcher
from surfgen.pipelines.config import load_config
from surfgen.pipelines.sampling import make_shape
from surfgen.pipelines.warmup import warm_shape_kernels

def compiled():
    out = {}
    for name, module in list(sys.modules.items()):
        if name.startswith("surfgen."):
            for attr, value in vars(module).items():
                if isinstance(value, CPUDispatcher):
                    out[name + "." + attr] = len(value.signatures)
    return out

warm_shape_kernels()
before = compiled()
config = load_config(None).with_grid(24)
accepted = 0
with tempfile.TemporaryDirectory() as tmp:
    for index in range(8):  # sculptures, lattices and free draws; accepted and rejected
        accepted += make_shape(index, seed=7, config=config, staging=Path(tmp), pictures=True).verdict.accepted
after = compiled()
grew = {k: [before.get(k, 0), v] for k, v in after.items() if v != before.get(k, 0)}
print(json.dumps({"kernels": sum(before.values()), "accepted": accepted, "grew": grew}))
"""


def test_sampled_shapes_compile_nothing_after_the_warm_up() -> None:
    out = subprocess.run(
        [sys.executable, "-c", CHECK], capture_output=True, text=True, timeout=600, check=True
    )
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["kernels"] >= 10 and result["accepted"] >= 1
    assert not result["grew"], f"compiled while sampling, not in the warm-up: {result['grew']}"
