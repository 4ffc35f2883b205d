"""`repro sweep --gpus 0,1 --runs-per-gpu N` (repro/launch/local.py): each child's environment, the packing of runs
on GPUs (never more than N at once on one GPU), and the bad input refused in one line. No GPU is needed: the
children here are stand-ins that record the environment they got."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from helpers import launch_app, write_sweep
from repro.launch import local
from repro.launch import spec as specs
from repro.launch.local import GpuPacking, child_env, parse_gpus

NO_GPU = "99" if torch.cuda.is_available() else "0"  # a GPU this machine lacks (no machine has 100)


def test_child_env_puts_cuda_and_egl_on_the_runs_gpu(monkeypatch):
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "0,1,2,3")  # the launcher's own view is replaced, not kept
    monkeypatch.delenv("MUJOCO_EGL_DEVICE_ID", raising=False)
    monkeypatch.delenv("MUJOCO_GL", raising=False)
    env = child_env(4, gpu=3)
    assert env["CUDA_VISIBLE_DEVICES"] == "3" and env["MUJOCO_EGL_DEVICE_ID"] == "3"
    assert env["CUDA_DEVICE_ORDER"] == "PCI_BUS_ID" and env["MUJOCO_GL"] == "egl"
    plain = child_env(4)
    assert plain["CUDA_VISIBLE_DEVICES"] == "0,1,2,3" and "MUJOCO_EGL_DEVICE_ID" not in plain


def test_parse_gpus_and_its_one_line_errors():
    assert parse_gpus("0, 2", 3) == GpuPacking((0, 2), 3) and GpuPacking((0, 2), 3).max_parallel == 6
    for text, per, needle in [("0,a", 1, "integers >= 0"), ("-1", 1, "integers >= 0"), ("", 1, "integers"),
                              ("1,1", 1, "twice"), ("0", 0, "--runs-per-gpu must be >= 1")]:
        with pytest.raises(ValueError, match=needle):
            parse_gpus(text, per)


def test_pick_fills_the_least_busy_gpu_and_never_more_than_n():
    packing = GpuPacking((0, 1), 2)
    running: list[int | None] = []
    for expected in (0, 1, 0, 1):
        gpu = packing.pick(running)
        assert gpu == expected
        running.append(gpu)
    assert packing.pick(running) is None  # 2 GPUs x 2 runs: full
    running.remove(1)
    assert packing.pick(running) == 1


def _sweep(tmp_path: Path, seeds: int) -> list[specs.PlannedRun]:
    path = write_sweep(tmp_path, "gpus", ["cheetah_run"], {"base": []}, seeds)
    sel = specs.Selection(sets=(f"runtime.results_root={specs.hydra_quote(str(tmp_path / 'runs'))}",))
    return specs.plan(specs.expand(specs.load(str(path)), sel))


def test_run_local_places_runs_on_gpus_at_most_n_at_once(tmp_path, monkeypatch):
    # Stand-in children: each records its GPU variables and its start and end, then exits without training
    # (so each run ends "failed"; the placement is what is tested).
    out = tmp_path / "children"
    out.mkdir()
    script = ("import json, os, sys, time; t0 = time.time(); time.sleep(0.6); "
              f"json.dump({{k: os.environ.get(k) for k in ('CUDA_VISIBLE_DEVICES', 'MUJOCO_EGL_DEVICE_ID')}} "
              f"| {{'start': t0, 'end': time.time()}}, open(os.path.join({str(out)!r}, str(os.getpid())), 'w'))")
    monkeypatch.setattr(local, "train_command", lambda overrides: [sys.executable, "-c", script])
    planned = _sweep(tmp_path, seeds=6)
    report = local.run_local(planned, "gpus", tmp_path / "state", 1, False, lambda _: None,
                             gpus=GpuPacking((0, 1), 2))
    assert len(report.started) == 6
    kids = [json.loads(p.read_text()) for p in out.iterdir()]
    assert len(kids) == 6
    assert all(k["CUDA_VISIBLE_DEVICES"] == k["MUJOCO_EGL_DEVICE_ID"] in ("0", "1") for k in kids)
    assert {k["CUDA_VISIBLE_DEVICES"] for k in kids} == {"0", "1"}
    for k in kids:  # at each child's start: the runs on its GPU then (itself included)
        on_gpu = [o for o in kids if o["CUDA_VISIBLE_DEVICES"] == k["CUDA_VISIBLE_DEVICES"]]
        assert sum(o["start"] <= k["start"] < o["end"] for o in on_gpu) <= 2
    # 4 slots for 6 runs of 0.6 s: some ran at once (the packing is used, not one run at a time)
    assert max(sum(o["start"] <= k["start"] < o["end"] for o in kids) for k in kids) >= 3


@pytest.mark.parametrize("args, needle", [
    (["--gpus", "0,x"], "integers >= 0"),
    (["--gpus", "0", "--runs-per-gpu", "0"], "--runs-per-gpu must be >= 1"),
    (["--gpus", "0", "--launcher", "slurm"], "--gpus is for the local launcher"),
    (["--runs-per-gpu", "2"], "--runs-per-gpu needs --gpus"),
    (["--gpus", "0", "--max-parallel", "2"], "drop --max-parallel"),
    (["--gpus", "0", "--warm-start"], "--warm-start"),
    # GPUs CUDA does not see as the runs would (issue 50.4: a run would have trained on the CPU)
    (["--gpus", NO_GPU], f"--gpus {NO_GPU}: torch sees no CUDA device {NO_GPU} on this machine; drop --gpus"),
])
def test_bad_gpu_options_are_one_line_exit_2(tmp_path, args, needle):
    res = CliRunner().invoke(launch_app(), ["sweep", "tiny", "--results", str(tmp_path), *args])
    assert res.exit_code == 2, res.output
    assert needle in res.output and len(res.output.strip().splitlines()) == 1, res.output
    assert "Traceback" not in res.output
    assert not any(tmp_path.iterdir())  # nothing started, nothing written under the results root
