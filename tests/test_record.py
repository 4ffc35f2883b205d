"""Recording during online runs (runtime.record=true) and `repro dataset make` from a recording."""

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch
import typer
from typer.testing import CliRunner

from helpers import REL, TINY, TINY_TACO, deterministic
from repro.agent.networks import Actor, Encoder
from repro.config.compose import compose, typed
from repro.data.dataset import check_dataset
from repro.data.record import Recorder, load_snapshot, snapshot_steps
from repro.runs import rundir
from repro.runs.console import Commands
from repro.train import make_dataset as mk
from repro.train.make_dataset_cli import register


def _cli() -> typer.Typer:
    app, dataset_app = typer.Typer(cls=Commands), typer.Typer()  # Commands: as `repro` catches a UserError

    @app.callback()
    def main() -> None:  # a group, so that `dataset make` is addressed as on the real CLI
        pass

    register(dataset_app)
    app.add_typer(dataset_app, name="dataset")
    return app


def run_make(*args: str):
    return CliRunner().invoke(_cli(), ["dataset", "make", *args])


# --------------------------------------------------------------------------- a synthetic recorded run (fast)
class _Policy:
    """What Recorder.snapshot reads from an agent (the real Agent's optimizers cost seconds to import)."""

    def __init__(self, rc):
        torch.manual_seed(0)
        self.encoder = Encoder((9, 84, 84))
        self.actor = Actor(self.encoder.repr_dim, 6, rc.agent.feature_dim, rc.agent.hidden_dim)
        self.stddev = rc.agent.stddev_schedule

    def acting_modules(self) -> dict[str, torch.nn.Module]:
        return {"encoder": self.encoder, "actor": self.actor}


def _synthetic_run(root: Path, lengths=(5, 7, 5, 6), returns=(0.0, 10.0, 4.0, 8.0), steps=(0, 10, 20, 23)) -> Path:
    """A run directory with a real config, recorded episodes of random frames and policy snapshots."""
    cfg = compose(TINY)
    rc = typed(cfg)
    path = root / REL
    path.mkdir(parents=True)
    rundir.write_config(path, cfg)
    rec = Recorder.open(path, rc.agent, (9, 84, 84), 6, None)
    rng = np.random.default_rng(0)
    for i, n in enumerate(lengths):
        rec.episode({"ep_id": np.array(i), "frames": rng.integers(0, 255, (n + 1, 3, 84, 84), dtype=np.uint8),
                     "actions": rng.uniform(-1, 1, (n, 6)).astype(np.float32),
                     "rewards": rng.uniform(0, 1, n).astype(np.float32), "discounts": np.ones(n, np.float32)})
    policy = _Policy(rc)
    for s, r in zip(steps, returns):
        rec.snapshot(policy, s, s * 2, r)
    return path


@pytest.fixture(scope="module")
def _template(tmp_path_factory) -> Path:
    return _synthetic_run(tmp_path_factory.mktemp("synthetic"))


@pytest.fixture
def synthetic(_template: Path, tmp_path: Path) -> Path:
    """A fresh copy of the synthetic run under ``tmp_path`` (its results root)."""
    shutil.copytree(_template.parents[4], tmp_path, dirs_exist_ok=True)
    return tmp_path / REL


def test_recorder_rewind_keeps_only_what_the_checkpoint_covers(synthetic: Path):
    run = synthetic
    rec_dir = run / "record"
    (rec_dir / "episodes" / ".ep_0000004.npz.abc.tmp").write_bytes(b"torn")
    rec = Recorder.open(run, typed(compose(TINY)).agent, (9, 84, 84), 6, {"counters": {"episode": 2, "step": 12}})
    assert rec.episodes.ids() == [0, 1]
    assert snapshot_steps(rec_dir / "snapshots") == [0, 10]  # the eval at step 12 (if any) runs after resume
    assert not list((rec_dir / "episodes").glob(".*.tmp"))
    Recorder.open(run, typed(compose(TINY)).agent, (9, 84, 84), 6, None)  # a start without checkpoint
    assert not list((rec_dir / "episodes").iterdir()) and not list((rec_dir / "snapshots").iterdir())


def test_snapshot_holds_what_acting_needs(synthetic: Path):
    run = synthetic
    snap = load_snapshot(run / "record" / "snapshots" / "step_000000010.pt")
    assert snap["step"] == 10 and snap["frame"] == 20 and snap["eval_return"] == 10.0
    assert snap["stddev"] == pytest.approx(typed(compose(TINY)).agent.stddev_schedule(10))
    assert snap["policy"] == {"obs_shape": [9, 84, 84], "action_dim": 6, "feature_dim": 50, "hidden_dim": 64}
    assert "convnet.0.weight" in snap["encoder"] and "policy.0.weight" in snap["actor"]


def test_medium_snapshot_is_nearest_the_fraction_of_the_best(synthetic: Path):
    source = mk.open_source(synthetic)
    assert [(s.step, s.eval_return) for s in source.snapshots] == [(0, 0.0), (10, 10.0), (20, 4.0), (23, 8.0)]
    assert mk.medium_snapshot(source, 0.5) == (source.snapshots[2], 10.0)  # 4 is nearest 5
    assert mk.medium_snapshot(source, 0.8)[0].step == 23
    assert mk.medium_snapshot(source, 0.0)[0].step == 0
    assert mk.medium_snapshot(source, 0.6)[0].step == 20  # 4 and 8 are both 2 from 6: the earliest


def _hashes(folder: Path) -> list[str]:
    return [e["sha256"] for e in mk.manifest_json(folder)["episodes"]]


def test_replay_kinds_from_a_synthetic_recording(synthetic: Path, tmp_path: Path):
    run = synthetic
    # medium at 0.5: the step-20 snapshot; episodes ending by step 20: 0 (5), 1 (12), 2 (17) -> 17 transitions
    out = mk.make(run, "medium-replay", transitions=10, seed=1, echo=lambda s: None)
    assert out == tmp_path / "datasets" / "cheetah_run" / "medium-replay"
    m = mk.manifest_json(out)
    assert m["source"]["snapshot_step"] == 20 and m["source"]["best_return"] == 10.0
    assert set(m["rule"]["source_episodes"]) <= {0, 1, 2} and m["transitions"] >= 10
    assert m["rule"]["pool_episodes"] == 3 and m["source"]["config_hash"] == mk.config_hash(rundir.saved_identity(run))
    for entry, ep_id in zip(m["episodes"], m["rule"]["source_episodes"]):
        with np.load(out / entry["file"]) as got, np.load(run / "record" / "episodes" / f"ep_{ep_id:07d}.npz") as src:
            for key in ("frames", "actions", "rewards", "discounts"):
                np.testing.assert_array_equal(got[key], src[key])
            assert entry["return"] == pytest.approx(float(src["rewards"].sum()))
    with pytest.raises(mk.MakeError, match="before step 20 .* holds 17 in 3 episodes"):
        mk.make(run, "medium-replay", transitions=18, out=tmp_path / "x", echo=lambda s: None)
    # full-replay: uniform over all 23 transitions; the same seed gives the same files, another seed may not
    a = mk.make(run, "full-replay", transitions=12, seed=5, out=tmp_path / "a", echo=lambda s: None)
    b = mk.make(run, "full-replay", transitions=12, seed=5, out=tmp_path / "b", echo=lambda s: None)
    assert _hashes(a) == _hashes(b) and mk.manifest_json(a)["rule"] == mk.manifest_json(b)["rule"]
    pool = mk.open_source(run).episodes
    draws = {tuple(e.ep_id for e in mk.draw_episodes(pool, 12, s, "x")) for s in range(20)}
    assert len(draws) > 1  # the draw depends on the seed
    assert not check_dataset(a)
    # the same request again is found made; another request at the same place is refused
    said = []
    assert mk.make(run, "full-replay", transitions=12, seed=5, out=a, echo=said.append) == a and "already" in said[0]
    with pytest.raises(mk.MakeError, match="holds another dataset"):
        mk.make(run, "full-replay", transitions=12, seed=6, out=a, echo=lambda s: None)


@pytest.mark.parametrize("breakage,needle", [
    ("no_config", "not a run directory"),
    ("no_record", "no recording"),
    ("gap", "gap"),
    ("done_count", "finished run had 9"),
    ("too_much", "holds 23 in 4 episodes"),
    ("other_task", "is a cheetah_run run, not hopper_hop"),
    ("partial_out", "holds no complete dataset"),
    ("bad_kind", "unknown kind"),
])
def test_bad_sources_get_one_line_and_exit_2(synthetic: Path, tmp_path: Path, breakage: str, needle: str):
    run = synthetic
    args = ["--source", str(run), "--kind", "full-replay", "--transitions", "5"]
    if breakage == "no_config":
        (run / "config.yaml").unlink()
    elif breakage == "no_record":
        shutil.rmtree(run / "record")
    elif breakage == "gap":
        (run / "record" / "episodes" / "ep_0000001.npz").unlink()
    elif breakage == "done_count":
        (run / "DONE").write_text(json.dumps({"episode": 9}))
    elif breakage == "too_much":
        args[-1] = "1000"
    elif breakage == "other_task":
        args += ["--task", "hopper_hop"]
    elif breakage == "partial_out":
        (tmp_path / "datasets" / "cheetah_run" / "full-replay" / "episodes").mkdir(parents=True)
    elif breakage == "bad_kind":
        args[3] = "expert"
    before = sorted(str(p) for p in tmp_path.rglob("*"))
    result = run_make(*args)
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], lines
    assert sorted(str(p) for p in tmp_path.rglob("*")) == before  # nothing written, nothing touched


# --------------------------------------------------------------------------- real tiny runs (slow)
# conftest's session runs: `tiny_taco` (unrecorded) and `tiny_taco_watched` (recorded); the SIGKILL-and-resume
# check of a recording is part of tests/test_train_e2e.py's kill-and-resume run.


@pytest.mark.slow
@pytest.mark.xdist_group(TINY_TACO)
def test_recorded_run_logs_equal_unrecorded_and_recording_is_complete(tiny_taco: Path, tiny_taco_watched: Path):
    unrecorded, recorded = tiny_taco, tiny_taco_watched
    for name in ("eval.csv", "train.csv"):
        pd.testing.assert_frame_equal(deterministic(recorded / name), deterministic(unrecorded / name))
    assert not (unrecorded / "record").exists()
    ev, tr = pd.read_csv(recorded / "eval.csv"), pd.read_csv(recorded / "train.csv")
    assert snapshot_steps(recorded / "record" / "snapshots") == list(ev["step"])
    for step, ret in zip(ev["step"], ev["episode_reward"]):
        assert load_snapshot(recorded / "record" / "snapshots" / f"step_{step:09d}.pt")["eval_return"] == \
            pytest.approx(ret)
    source = mk.open_source(recorded)
    assert [e.ep_id for e in source.episodes] == list(range(len(tr)))
    assert [e.end_step for e in source.episodes] == list(tr["step"])
    np.testing.assert_allclose([e.ret for e in source.episodes], tr["episode_reward"], rtol=1e-5)
    final = load_snapshot(recorded / "record" / "snapshots" / f"step_{ev['step'].iloc[-1]:09d}.pt")
    ckpt = torch.load(recorded / "checkpoint.pt", weights_only=True)
    for k, v in ckpt["agent"]["actor"].items():
        assert torch.equal(final["actor"][k], v)  # the last snapshot is the trained actor
    for ep_id in range(len(tr)):  # the replay (capacity 2000) kept everything: same arrays, no second copy
        a, b = source.episodes[ep_id].path, recorded / "replay" / f"ep_{ep_id:07d}.npz"
        assert os.stat(a).st_ino == os.stat(b).st_ino or a.read_bytes() == b.read_bytes()


@pytest.mark.slow
@pytest.mark.xdist_group(TINY_TACO)
def test_make_each_kind_from_a_recorded_run(tiny_taco: Path, tiny_taco_watched: Path, tmp_path: Path):
    unrecorded, recorded = tiny_taco, tiny_taco_watched
    source = mk.open_source(recorded)
    best = max(s.eval_return for s in source.snapshots)
    last = source.snapshots[-1]
    fraction = last.eval_return / best if best else 0.0  # targets the last snapshot: episodes exist before it
    assert mk.medium_snapshot(source, fraction)[0].step == last.step
    res = run_make("--source", str(recorded), "--kind", "medium-replay", "--transitions", "100",
                   "--medium-fraction", str(fraction), "--seed", "2", "--out", str(tmp_path / "mr"))
    assert res.exit_code == 0, res.output
    m = mk.manifest_json(tmp_path / "mr")
    assert m["source"]["snapshot_step"] == last.step and m["transitions"] >= 100
    assert all(source.episodes[i].end_step <= last.step for i in m["rule"]["source_episodes"])
    res = run_make("--source", str(recorded), "--kind", "full-replay", "--transitions", "150", "--seed", "2")
    assert res.exit_code == 0, res.output
    full = recorded.parents[4] / "datasets" / "cheetah_run" / "full-replay"
    assert mk.manifest_json(full)["transitions"] == 150 and not check_dataset(full)
    # medium: rollouts of the snapshot policy with its exploration noise, on fresh episode seeds
    a = mk.make(recorded, "medium", transitions=60, seed=4, out=tmp_path / "m1", device="cpu", echo=lambda s: None)
    m = mk.manifest_json(a)
    snap_step = m["source"]["snapshot_step"]
    snap = load_snapshot(recorded / "record" / "snapshots" / f"step_{snap_step:09d}.pt")
    assert m["kind"] == "medium" and m["transitions"] == 100 and len(m["episodes"]) == 2  # whole 50-step episodes
    assert m["rule"]["stddev"] == snap["stddev"] > 0
    with np.load(a / m["episodes"][0]["file"]) as z, np.load(source.episodes[0].path) as train0:
        assert z["frames"].shape == (51, 3, 84, 84) and z["actions"].shape == (50, 6)
        assert not np.array_equal(z["frames"][0], train0["frames"][0])  # not the training episode's seed
        assert m["episodes"][0]["return"] == pytest.approx(float(z["rewards"].sum(dtype=np.float64)))
        enc, actor = Encoder((9, 84, 84)), Actor(32 * 35 * 35, 6, 50, 64)
        enc.load_state_dict(snap["encoder"])
        actor.load_state_dict(snap["actor"])
        obs = torch.as_tensor(np.concatenate([z["frames"][0]] * 3)).float().unsqueeze(0)
        with torch.no_grad():
            mean = actor(enc(obs), 1.0).mean.numpy()[0]
        noise = z["actions"][0] - mean
        assert 1e-4 < np.abs(noise).max() and np.abs(noise).max() < 6 * snap["stddev"]  # noisy, around the mean
    # deterministic for a seed; killed at any moment and re-run: complete and the same
    proc = subprocess.Popen([sys.executable, "-c", (
        "import sys; from repro.train.make_dataset import make; "
        f"make({str(recorded)!r}, 'medium', transitions=60, seed=4, out={str(tmp_path / 'm2')!r}, device='cpu')")],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    staging = tmp_path / ".m2.partial" / "episodes"
    t0 = time.time()
    while proc.poll() is None and not (staging.is_dir() and any(staging.glob("ep_*.npz"))) and time.time() - t0 < 300:
        time.sleep(0.05)
    assert proc.poll() is None, "make finished before it could be killed"
    proc.kill()
    proc.wait()
    assert not (tmp_path / "m2").exists()  # a partial dataset never sits where a dataset is looked for
    b = mk.make(recorded, "medium", transitions=60, seed=4, out=tmp_path / "m2", device="cpu", echo=lambda s: None)
    assert _hashes(a) == _hashes(b) and not check_dataset(b) and not (tmp_path / ".m2.partial").exists()
    # an unrecorded source
    res = run_make("--source", str(unrecorded), "--kind", "medium")
    assert res.exit_code == 2 and "no recording" in res.stderr and len(res.stderr.strip().splitlines()) == 1


def test_a_snapshot_keeps_the_modules_the_learner_s_acting_hook_names(tmp_path):
    """``runtime.record=true`` for any online learner implementing the protocol (issue 35): the snapshot holds what
    ``acting_modules()`` returns, not what ``modules()`` happens to call "encoder" and "actor"."""
    from repro.data.record import PolicySpec, snapshot_path

    class NotOnTheBackbone:
        def acting_modules(self) -> dict[str, torch.nn.Module]:
            return {"encoder": torch.nn.Linear(2, 3), "actor": torch.nn.Linear(3, 1)}

        def stddev(self, step: int) -> float:
            return 0.25

        def modules(self) -> dict[str, torch.nn.Module]:
            raise AssertionError("the recorder reads acting_modules()")

    rec = Recorder(tmp_path, PolicySpec((9, 8, 8), 1, 3, 3))
    rec.snapshot(NotOnTheBackbone(), step=10, frame=20, eval_return=1.5)  # type: ignore[arg-type]
    snap = load_snapshot(snapshot_path(rec.snapshots, 10))
    assert snap["encoder"]["weight"].shape == (3, 2) and snap["actor"]["weight"].shape == (1, 3)
    assert (snap["stddev"], snap["step"], snap["eval_return"]) == (0.25, 10, 1.5)
