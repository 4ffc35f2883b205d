"""`repro doctor` (repro/launch/doctor.py) and the SLURM status pieces that need no cluster: the GPU and device
rules, sacct's rows of arrays that never started, a cancelled job's status, and the doctor command end to end
(real rendering, a real dataset). The SLURM preflight itself runs on the local cluster (tests/test_slurm.py)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from helpers import write_sweep
from offline_fixtures import write_dataset
from repro.launch import spec as specs
from repro.launch.doctor import (
    FAIL,
    OK,
    WARN,
    DoctorInputs,
    cuda_check,
    dataset_check,
    gpu_check,
    results_root_check,
    run_checks,
    versions_check,
)
from repro.launch.slurm_query import _array_tasks, explain
from repro.launch.state import RunRecord, state_dir, write_record
from repro.launch.status import run_status


def test_egl_and_cuda_name_the_same_gpu_by_pci_id_or_by_index():
    same = gpu_check({"CUDA_VISIBLE_DEVICES": "1"}, {"index": 0, "pci": "0000:3b:00.0"}, "00000000:3B:00.0")
    assert same.status == OK and "0000:3b:00.0" in same.detail
    other = gpu_check({"CUDA_VISIBLE_DEVICES": "1", "MUJOCO_EGL_DEVICE_ID": "1"}, {"index": 1, "pci": "0000:1a:00.0"},
                      "00000000:3B:00.0")
    assert other.status == FAIL and "0000:1a:00.0" in other.detail and "MUJOCO_EGL_DEVICE_ID" in other.detail
    by_index = gpu_check({"CUDA_VISIBLE_DEVICES": "2,3", "MUJOCO_EGL_DEVICE_ID": "0"}, {}, None)
    assert by_index.status == FAIL and "MUJOCO_EGL_DEVICE_ID=2" in by_index.detail
    assert gpu_check({"CUDA_VISIBLE_DEVICES": "2", "MUJOCO_EGL_DEVICE_ID": "2"}, {}, None).status == OK
    assert gpu_check({"CUDA_VISIBLE_DEVICES": "0"}, {"index": 0, "software": True}, None).status == WARN
    assert gpu_check({}, {"index": 0, "software": True}, None).status == OK


def test_the_runs_device_against_the_gpus_torch_sees():
    cpu_torch = {"version": "2.13.0+cpu", "cuda": None, "count": 0}
    allocated = cuda_check(["auto"], cpu_torch, "0")
    assert allocated.status == FAIL and "would train on the CPU" in allocated.detail and "CPU-only" in allocated.detail
    assert cuda_check(["cuda"], cpu_torch, None).status == FAIL
    assert cuda_check(["cpu"], cpu_torch, "0").status == WARN
    assert cuda_check(["auto"], cpu_torch, None).status == OK
    gpu_torch = {"version": "2.5.1+cu121", "cuda": "12.1", "count": 1, "name": "H100"}
    assert cuda_check(["cuda:1"], gpu_torch, "0").status == FAIL
    assert cuda_check(["auto"], gpu_torch, "0").status == OK


def test_versions_are_printed_beside_their_pins_and_a_results_root_that_is_a_file_fails(tmp_path):
    check = versions_check({"version": "2.13.0+cpu", "cuda": None})
    for name in ("torch 2.13.0+cpu (CUDA none) [pin", "mujoco ", "dm-control ", "metaworld "):
        assert name in check.detail, check.detail
    assert check.status == OK, check.detail  # this environment is the pinned one
    (tmp_path / "file").write_text("x")
    assert results_root_check(tmp_path / "file" / "runs").status == FAIL
    assert results_root_check(tmp_path / "new" / "runs").status == OK and not (tmp_path / "new").exists()


def test_sacct_rows_of_an_array_that_never_started_name_each_task():
    assert _array_tasks("[0-3%2]") == {"0", "1", "2", "3"}
    assert _array_tasks("[1,4-5]") == {"1", "4", "5"}
    assert _array_tasks("7") is None
    assert explain("PartitionConfig").startswith("PartitionConfig: no node of the partition")
    assert explain("SomethingNew") == "SomethingNew"


def test_a_job_cancelled_before_it_started_shows_as_cancelled(tmp_path):
    sweep = write_sweep(tmp_path, "cx", ["reacher_hard"], {"base": []}, 1)
    (p,) = specs.plan(specs.expand(specs.load(str(sweep)), specs.Selection(sets=(f"runtime.results_root={tmp_path}",))))
    sdir = state_dir(tmp_path, "cx")
    write_record(sdir, RunRecord(key=p.key, run_dir=str(p.run_dir), overrides=[], launcher="slurm", status="queued",
                                 job_id="12_0"))
    got = run_status(p.key, p.run_dir, tmp_path, sdir, {"12_0": "CANCELLED"})
    assert got.status == "cancelled" and "before it started" in got.detail
    assert run_status(p.key, p.run_dir, tmp_path, sdir, {"12_0": "FAILED"}).status == "failed"


def test_dataset_check_hashes_every_episode_file_as_the_dataset_reader_does(tmp_path):
    """The doctor's streamed sha256 of each episode file is the one the manifest records (the dataset module's
    episode_digest): an intact dataset passes with its file count; one flipped byte in the third file fails naming
    that file and no other."""
    folder = write_dataset(tmp_path / "medium", task="cheetah_run", action_dim=6)
    files = sorted((folder / "episodes").glob("*.npz"))
    ok = dataset_check("medium", folder)
    assert ok.status == OK and f": {len(files)} episode files match their sha256" in ok.detail, ok
    raw = bytearray(files[2].read_bytes())
    raw[len(raw) // 2] ^= 0x01
    files[2].write_bytes(bytes(raw))
    bad = dataset_check("medium", folder)
    assert bad.status == FAIL and f"{files[2].name}: sha256 differs from the manifest" in bad.detail, bad
    assert "more)" not in bad.detail, bad


@pytest.mark.slow  # a sweep planned, torch imported and a renderer started in a subprocess: seconds
def test_doctor_names_a_broken_renderer_and_a_corrupt_dataset_in_one_line(tmp_path):
    """`repro doctor tiny_offline`: its full-replay dataset is not made yet (a warning: those runs wait), its medium
    one has a corrupt episode file and MUJOCO_GL names no backend: exit 1, one error line naming both checks."""
    medium = write_dataset(tmp_path / "datasets" / "cheetah_run" / "medium", task="cheetah_run", action_dim=6)
    episode = medium / "episodes" / "ep_0000001.npz"
    raw = bytearray(episode.read_bytes())
    raw[-40] ^= 0xFF
    episode.write_bytes(bytes(raw))
    env = dict(os.environ, MUJOCO_GL="nogl")
    res = subprocess.run([sys.executable, "-m", "repro", "doctor", "tiny_offline", "-r", str(tmp_path)],
                         capture_output=True, text=True, env=env, timeout=300)
    errors = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == 1 and len(errors) == 1, res.stdout + res.stderr
    assert errors[0].startswith("error: render: MuJoCo cannot render with MUJOCO_GL=nogl"), errors
    assert "; dataset: dataset medium for cheetah_run at " in errors[0] and "ep_0000001.npz: sha256" in errors[0]
    assert "warn  dataset       dataset full-replay for cheetah_run" in res.stdout, res.stdout


def test_doctor_passes_here(tmp_path, monkeypatch):
    """On this machine (the test environment renders with EGL): every check passes, the frame is rendered."""
    monkeypatch.delenv("CUDA_VISIBLE_DEVICES", raising=False)
    monkeypatch.delenv("MUJOCO_EGL_DEVICE_ID", raising=False)
    report = run_checks(DoctorInputs(str(tmp_path), ("reacher_hard",), ("cpu",)))
    assert not report.failed, [c.line() for c in report.checks]
    render = next(c for c in report.checks if c.name == "render")
    assert render.detail.startswith("reacher_hard 9x84x84 in "), render.detail
    assert Path(tmp_path).is_dir() and not list(Path(tmp_path).iterdir()), "the doctor leaves nothing behind"
