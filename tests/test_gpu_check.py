"""benchmarks/gpu_check.sh's CPU side: with GPU_CHECK_DEVICE=cpu GPU_CHECK_QUICK=1 it runs every step at tiny sizes
and writes its JSON under $OUT (the GPU numbers themselves are measured on a GPU, docs/performance.md)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from repro.bench.e2e import PHASES

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
@pytest.mark.device_script
def test_gpu_check_quick_on_cpu_writes_every_json(tmp_path):
    out = tmp_path / "out"
    env = dict(os.environ, OUT=str(out), GPU_CHECK_DEVICE="cpu", GPU_CHECK_QUICK="1", PYTHON=sys.executable,
               OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    proc = subprocess.run(["bash", str(ROOT / "benchmarks" / "gpu_check.sh")], env=env, capture_output=True,
                          text=True, timeout=300)
    log = (out / "gpu_check.log").read_text() if (out / "gpu_check.log").exists() else ""
    assert proc.returncode == 0, proc.stdout + proc.stderr + log[-3000:]
    summary = json.loads((out / "gpu_check.json").read_text())
    status = {s["step"]: s["status"] for s in summary["steps"]}
    assert status == {"bench": "ok", "e2e": "ok", "e2e_overlap": "ok", "amp_check": "ok", "fast_check": "ok",
                      "graphs": "skipped", "pack2": "ok", "pack4": "ok", "compile": "skipped"}, log[-3000:]
    bench = json.loads((out / "bench.json").read_text())
    assert {r["path"] for r in bench["results"]} == {"plain", "amp", "fast"}
    assert {(e["path"], e["phase_sync"]) for e in bench["e2e"]} == {(p, s) for p in ("plain", "fast")
                                                                        for s in (True, False)}
    assert all(set(e["phases"]) == set(PHASES) for e in bench["e2e"])
    amp = json.loads((out / "amp_check.json").read_text())
    assert len(amp["plain"]) == len(amp["amp"]) == 2 and amp["per_loss"]
    fast = json.loads((out / "fast_check.json").read_text())
    assert len(fast["plain"]) == len(fast["fast"]) == 2 and fast["per_loss"]
    packing = json.loads((out / "packing.json").read_text())["packing"]
    for n in ("2", "4"):
        assert len(packing[n]["runs"]) == int(n), packing
        assert packing[n]["fps_together"] > 0, packing
