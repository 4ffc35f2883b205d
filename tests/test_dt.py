"""Decision Transformer learner (repro/learners/dt.py) and its hooks in the offline loop: training on episode
windows, return-conditioned acting, exact resume, two evaluation targets, and a tiny end-to-end run."""

from __future__ import annotations

import io
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
import torch
from typer.testing import CliRunner

from offline_fixtures import make_episode, write_dataset
from repro.config.compose import compose, typed  # noqa: E402
from repro.data.dataset import load_manifest  # noqa: E402
from repro.data.offline_replay import load_offline_episodes  # noqa: E402
from repro.learners import (  # noqa: E402
    LEARNERS,
    EpisodicActor,
    Learner,
    ReturnConditioned,
    SequenceLearner,
    build_learner,
    samples_episodes,
)
from repro.learners.dt import DT  # noqa: E402
from repro.learners.losses.dt import action_loss  # noqa: E402
from repro.runs.checkpoint import load_checkpoint, save_checkpoint  # noqa: E402
from repro.runs.runformat import OFFLINE_EVAL_COLUMNS, RETURN_TARGET_EVAL_COLUMNS, offline_eval_columns  # noqa: E402
from repro.train import api, build  # noqa: E402
from repro.train.common import run_eval_episodes  # noqa: E402
from repro.train.offline_loop import OfflineLogger, OfflineLoop  # noqa: E402
from repro_app.cli import app  # noqa: E402

OBS = (9, 32, 32)
A_DIM = 4
SMALL = {"agent.dt.context": 4, "agent.dt.embed_dim": 16, "agent.dt.n_layers": 1, "agent.dt.batch_size": 6,
         "agent.dt.dropout": 0.0, "agent.dt.warmup_steps": 1, "agent.dt.lr": 1e-3}


def _dt(seed: int = 0, **over) -> DT:
    values = {**SMALL, **over}
    rc = typed(compose(["agent=dt", "profile=tiny", "task=hopper_hop"] + [f"{k}={v}" for k, v in values.items()]))
    torch.manual_seed(seed)
    learner = build_learner(rc.agent, OBS, A_DIM, "cpu")
    assert isinstance(learner, DT)
    return learner


def _episodes(lengths=(7, 5, 9)) -> list[dict[str, np.ndarray]]:
    rng = np.random.default_rng(0)
    return [make_episode(i, n, (3, 32, 32), A_DIM, rng) for i, n in enumerate(lengths)]


# ----------------------------------------------------------------------------- learner
def test_config_defaults_are_the_dt_papers():
    rc = typed(compose(["agent=dt", "task=cheetah_run"]))
    d = rc.agent.dt
    assert (d.context, d.embed_dim, d.n_layers, d.n_heads, d.dropout) == (20, 128, 3, 1, 0.1)
    assert (d.lr, d.weight_decay, d.warmup_steps, d.grad_clip, d.batch_size, d.rtg_scale) == \
        (1e-4, 1e-4, 10_000, 0.25, 64, 1e-3)
    assert rc.agent.name == "dt" and rc.agent.learner == "dt" and rc.agent.batch_size == 64


def test_protocol_registry_and_parameter_table():
    learner = _dt()
    assert LEARNERS["dt"] is DT and samples_episodes("dt") and not samples_episodes("bc")
    for proto in (Learner, SequenceLearner, EpisodicActor, ReturnConditioned):
        assert isinstance(learner, proto), proto
    rows = learner.parameter_counts()
    assert [n for n, _ in rows] == ["encoder", "embeddings", "transformer", "head"]
    assert sum(c for _, c in rows) == sum(p.numel() for p in learner.model.parameters())
    assert learner.batch_size == 6 and learner.resolved["batch_size"] == 6
    group = learner.optimizer.param_groups[0]
    assert isinstance(learner.optimizer, torch.optim.AdamW) and group["weight_decay"] == 1e-4


def test_update_reduces_the_loss_on_a_tiny_dataset():
    learner = _dt()
    sampler = learner.make_sampler(_episodes(), seed=0)
    batch = sampler.sample(6)
    before = {k: v.clone() for k, v in learner.model.encoder.state_dict().items()}
    first = learner.update(batch, 0)
    assert set(first) == set(learner.metric_names()) == {"dt_loss", "lr", "grad_norm"}
    assert any(not torch.equal(before[k], v) for k, v in learner.model.encoder.state_dict().items())
    for step in range(1, 40):
        last = learner.update(batch, step)
    assert last["dt_loss"] < 0.3 * first["dt_loss"]


def test_warmup_and_gradient_clip():
    learner = _dt(**{"agent.dt.warmup_steps": 4, "agent.dt.grad_clip": 1e-3})
    sampler = learner.make_sampler(_episodes(), seed=0)
    lrs = [learner.update(sampler.sample(6), u)["lr"] for u in range(6)]
    assert lrs == pytest.approx([1e-3 * m for m in (0.25, 0.5, 0.75, 1.0, 1.0, 1.0)], rel=1e-12)
    params = [p for p in learner.model.parameters()]
    batch = sampler.sample(6)
    learner.optimizer.zero_grad(set_to_none=True)
    pred = learner.model(*(torch.as_tensor(batch[k]) for k in ("frames", "actions", "rtg", "timesteps", "mask")))
    action_loss(pred, torch.as_tensor(batch["actions"]), torch.as_tensor(batch["keep"])).backward()
    raw = torch.norm(torch.stack([p.grad.norm() for p in params if p.grad is not None]))
    learner.optimizer.zero_grad(set_to_none=True)
    metrics = learner.update(batch, 6)
    clipped = torch.norm(torch.stack([p.grad.norm() for p in params if p.grad is not None]))
    assert metrics["grad_norm"] == pytest.approx(raw.item(), rel=1e-4) and raw > 1e-3
    assert clipped.item() == pytest.approx(1e-3, rel=1e-3)


def _spy(learner: DT) -> list[dict[str, np.ndarray]]:
    """Record every model input of ``learner.act`` (numpy copies); the model still runs."""
    seen: list[dict[str, np.ndarray]] = []
    forward = learner.model.forward

    def spy(frames, actions, rtg, timesteps, mask):
        out = forward(frames, actions, rtg, timesteps, mask)
        seen.append({"frames": frames.numpy().copy(), "actions": actions.numpy().copy(), "rtg": rtg.numpy().copy(),
                     "timesteps": timesteps.numpy().copy(), "mask": mask.numpy().copy(), "out": out.numpy().copy()})
        return out

    learner.model.forward = spy  # type: ignore[method-assign]
    return seen


def test_act_feeds_the_history_known_answer():
    learner = _dt()
    learner.train(False)
    seen = _spy(learner)
    k, scale, target = 4, 1e-3, 500.0
    rng = np.random.default_rng(1)
    obs = [rng.integers(0, 256, OBS, dtype=np.uint8) for _ in range(7)]
    rewards = [3.0, 1.5, 0.0, 7.25, 2.0, 4.0, 1.0]
    learner.set_target_return(target)
    learner.begin_episode()
    taken = []
    for t in range(7):
        action = learner.act(obs[t], t, eval_mode=True)
        x = seen[-1]
        assert np.array_equal(action, x["out"][0, -1])  # the prediction at the newest step
        real = min(t + 1, k)
        steps = list(range(t + 1 - real, t + 1))
        assert x["mask"][0].tolist() == [False] * (k - real) + [True] * real
        assert x["timesteps"][0, k - real:].tolist() == steps
        for slot, s in zip(range(k - real, k), steps):
            assert np.array_equal(x["frames"][0, slot], obs[s])
            want_action = taken[s] if s < t else np.zeros(A_DIM)  # the current step's action is a placeholder
            assert np.array_equal(x["actions"][0, slot], want_action)
            assert x["rtg"][0, slot, 0] == pytest.approx((target - sum(rewards[:s])) * scale, abs=1e-6)
        taken.append(action.copy())
        learner.observe(action, rewards[t])
    learner.begin_episode()  # a new episode forgets the history and restarts at the target
    learner.act(obs[0], 0, eval_mode=True)
    assert seen[-1]["mask"][0].tolist() == [False, False, False, True]
    assert seen[-1]["rtg"][0, -1, 0] == pytest.approx(target * scale)


class _CountingEnv:
    """A 5-step environment whose reward at step t is t + 1 and whose observation marks t."""

    spec = SimpleNamespace(has_success=False, obs_shape=OBS, action_dim=A_DIM)

    def reset(self, seed: int):
        self.t = 0
        return self._ts(0.0)

    def step(self, action):
        self.t += 1
        return self._ts(float(self.t))

    def _ts(self, reward: float):
        obs = np.zeros(OBS, dtype=np.uint8)
        obs[:, 0, 0] = self.t
        return SimpleNamespace(observation=obs, reward=reward, last=self.t >= 5, info={})

    def close(self) -> None:
        pass


class _TargetEnv(_CountingEnv):
    """Rewards that depend on the action taken; logs (the learner's target, the episode's return)."""

    def __init__(self, learner: DT):
        self.learner, self.log = learner, []

    def reset(self, seed: int):
        self.total = 0.0
        return super().reset(seed)

    def step(self, action):
        ts = super().step(action)
        ts.reward = float(ts.reward + action[0])
        self.total += ts.reward
        if ts.last:
            self.log.append((self.learner.target_return, self.total))
        return ts


def test_eval_rollouts_drive_the_episodic_hooks():
    learner = _dt()
    seen = _spy(learner)
    learner.set_target_return(100.0)
    result = run_eval_episodes(_CountingEnv(), learner, 2, 0, 0, 0)
    assert result.returns == [15.0, 15.0] and len(seen) == 10
    last = seen[4]  # episode 0, step 4: the last 4 steps, rtg decremented by the rewards 1, 2, 3, 4
    assert last["rtg"][0, :, 0] == pytest.approx([(100 - 1) * 1e-3, (100 - 3) * 1e-3, (100 - 6) * 1e-3,
                                                   (100 - 10) * 1e-3], abs=1e-6)
    assert seen[5]["mask"][0].tolist() == [False, False, False, True]  # begin_episode() before episode 1
    assert learner.training  # train mode restored


def test_state_dict_round_trip_gives_the_identical_next_updates(tmp_path: Path):
    episodes = _episodes()
    a = _dt(seed=0, **{"agent.dt.warmup_steps": 10, "agent.dt.dropout": 0.1})
    sampler = a.make_sampler(episodes, seed=3)
    for u in range(3):
        a.update(sampler.sample(6), u)
    save_checkpoint(tmp_path / "c.pt", a.state_dict())
    torch.manual_seed(7)
    want = [a.update(sampler.sample(6), u) for u in range(3, 5)]

    b = _dt(seed=1, **{"agent.dt.warmup_steps": 10, "agent.dt.dropout": 0.1})
    other = b.make_sampler(episodes, seed=99)
    b.load_state_dict(load_checkpoint(tmp_path / "c.pt"))  # weights_only: plain tensors and containers
    torch.manual_seed(7)
    got = [b.update(other.sample(6), u) for u in range(3, 5)]
    assert got == want
    for (name, p), q in zip(a.model.state_dict().items(), b.model.state_dict().values()):
        assert torch.equal(p, q), name


# ----------------------------------------------------------------------------- offline loop hooks
def _loop(tmp_path: Path, learner: DT, data_dir: Path, updates: int, eval_episodes: int,
             env=None, state: dict | None = None, saved: list | None = None):
    data = load_offline_episodes(data_dir, task="hopper_hop", action_dim=A_DIM, frame_shape=(3, 32, 32))
    assert data.buffer is None and data.episodes is not None and len(data.episodes) == 3
    cfg = typed(compose(["agent=dt", "profile=tiny", "task=hopper_hop", f"offline.updates={updates}",
                         "offline.eval_every_updates=2", f"offline.eval_episodes={eval_episodes}",
                         "offline.checkpoint_every_updates=2", "offline.log_every_updates=1"])).offline
    logger = OfflineLogger(tmp_path, learner.metric_names(), offsets=state["csv"] if state else None,
                           echo=lambda s: None, return_conditioned=True)
    loop = OfflineLoop(cfg, 1, 2, env or SimpleNamespace(spec=SimpleNamespace(has_success=False)), learner,
                             build.batch_source(learner, data, 1), logger,
                             (lambda s: saved.append(_frozen(s))) if saved is not None else (lambda s: None),
                             (200.0, "source"), data.digest, dataset_best_return=data.best_return)
    if state is not None:
        loop.restore(state)
    return loop, logger, data


def _frozen(state: dict) -> dict:
    """A checkpoint as written and read back (state dicts hold live tensors)."""
    buf = io.BytesIO()
    torch.save(state, buf)
    buf.seek(0)
    return torch.load(buf, weights_only=True)


def _deterministic(csv: Path) -> pd.DataFrame:
    df = pd.read_csv(csv)
    return df.drop(columns=["total_time", "updates_per_s"], errors="ignore")


def test_offline_loop_resume_from_checkpoint_is_exact(tmp_path: Path):
    data_dir = write_dataset(tmp_path / "d", frame_shape=(3, 32, 32), best_return=200.0)
    over = {"agent.dt.warmup_steps": 10, "agent.dt.dropout": 0.1}
    torch.manual_seed(0)
    saved: list[dict] = []
    (tmp_path / "ref").mkdir()
    loop, logger, _ = _loop(tmp_path / "ref", _dt(**over), data_dir, 6, 0, saved=saved)
    loop.run()
    logger.close()
    mid = next(s for s in saved if s["offline"]["update"] == 2)
    assert set(mid["learner"]) == {"schedulers", "sampler"}
    (tmp_path / "resumed").mkdir()
    for name in ("train.csv", "eval.csv"):  # the rows written up to the checkpoint
        (tmp_path / "resumed" / name).write_bytes((tmp_path / "ref" / name).read_bytes()[:mid["csv"][name[:-4]]])
    loop, logger, _ = _loop(tmp_path / "resumed", _dt(seed=5, **over), data_dir, 6, 0, state=mid)
    assert loop.update == 2
    loop.run()
    logger.close()
    ref, res = _deterministic(tmp_path / "ref" / "train.csv"), _deterministic(tmp_path / "resumed" / "train.csv")
    assert list(ref["update"]) == [1, 2, 3, 4, 5, 6]
    pd.testing.assert_frame_equal(res, ref)


def test_offline_loop_evaluates_at_both_targets(tmp_path: Path):
    data_dir = write_dataset(tmp_path / "d", frame_shape=(3, 32, 32), best_return=200.0)
    best = float(load_manifest(data_dir).returns.max())
    learner = _dt()
    env = _TargetEnv(learner)
    (tmp_path / "run").mkdir()
    loop, logger, data = _loop(tmp_path / "run", learner, data_dir, 2, 1, env=env)
    assert data.best_return == best == max(float(e["rewards"].sum()) for e in data.episodes) != 200.0
    loop.run()
    logger.close()
    ev = pd.read_csv(tmp_path / "run" / "eval.csv")
    assert list(ev.columns) == offline_eval_columns(True) == OFFLINE_EVAL_COLUMNS + RETURN_TARGET_EVAL_COLUMNS
    assert list(ev["update"]) == [0, 2] and len(env.log) == 4  # 2 evaluations x 2 targets x 1 episode
    assert (ev["target_return"] == 200.0).all() and (ev["target_reference"] == "source").all()
    assert (ev["dataset_target_return"] == best).all()
    online = [ret for target, ret in env.log if target == 200.0]
    dataset = [ret for target, ret in env.log if target == best]
    assert online != dataset  # the conditioning changes the actions, the actions the rewards
    assert list(ev["episode_reward"]) == pytest.approx(online, abs=1e-12)
    assert list(ev["episode_reward_dataset_target"]) == pytest.approx(dataset, abs=1e-12)
    assert np.allclose(ev["normalized_score"], 100 * ev["episode_reward"] / 200.0)
    assert np.allclose(ev["normalized_score_dataset_target"], 100 * ev["episode_reward_dataset_target"] / 200.0)
    # without an online reference the primary target falls back to the dataset's best
    loop.reference_return, loop.reference_kind = None, "none"
    assert loop.eval_targets() == [(best, "dataset"), (best, "dataset")]


# ----------------------------------------------------------------------------- CLI and end to end
TINY = ["agent=dt", "task=cheetah_run", "profile=tiny", "seed=2", "runtime.threads=1", "offline.dataset=medium",
        "offline.updates=4", "offline.eval_every_updates=2", "offline.eval_episodes=1",
        "offline.checkpoint_every_updates=2", "offline.log_every_updates=2",
        "agent.dt.batch_size=4", "agent.dt.context=5", "agent.dt.embed_dim=32", "agent.dt.n_layers=1"]


def test_dry_run_without_dataset_on_disk(tmp_path: Path):
    out = CliRunner().invoke(app, ["train", *TINY, f"runtime.results_root={tmp_path}", "--dry-run"])
    assert out.exit_code == 0, out.output
    for row in ("│ encoder", "│ embeddings", "│ transformer", "│ head"):
        assert row in out.output, row
    assert "context: 5" in out.output and not (tmp_path / "default").exists()


def test_dt_loads_episodes_not_a_replay(tmp_path: Path):
    write_dataset(tmp_path / "datasets" / "cheetah_run" / "medium", task="cheetah_run", action_dim=6)
    data = build.load_dataset(typed(compose(TINY + [f"runtime.results_root={tmp_path}"])))
    assert data.buffer is None and data.episodes is not None
    assert [len(e["actions"]) for e in data.episodes] == [12, 9, 15]
    assert data.raw_frame_bytes == (12 + 9 + 15 + 3) * 3 * 84 * 84
    bc = build.load_dataset(typed(compose(["agent=bc", *TINY[1:11], f"runtime.results_root={tmp_path}"])))
    assert bc.buffer is not None and bc.episodes is None


def test_episode_longer_than_the_timestep_embedding_is_one_line(tmp_path: Path):
    write_dataset(tmp_path / "datasets" / "cheetah_run" / "medium", task="cheetah_run", action_dim=6)
    out = CliRunner().invoke(app, ["train", *TINY, "agent.dt.max_timestep=10", f"runtime.results_root={tmp_path}",
                                   "--no-progress"])
    lines = [ln for ln in out.output.strip().splitlines() if ln]
    assert out.exit_code == 2 and len(lines) == 1 and "max_timestep" in lines[0], out.output
    assert not (tmp_path / "default").exists()


@pytest.mark.slow
def test_dt_end_to_end_run_logs_both_targets(tmp_path: Path):
    data_dir = write_dataset(tmp_path / "datasets" / "cheetah_run" / "medium", task="cheetah_run", action_dim=6,
                             best_return=200.0)
    run = api.train(TINY + [f"runtime.results_root={tmp_path}"], echo=lambda s: None)
    ev = pd.read_csv(run / "eval.csv")
    assert list(ev.columns) == offline_eval_columns(True)
    assert list(ev["update"]) == [0, 2, 4] and (ev["eval_episodes"] == 1).all()
    assert (ev["target_return"] == 200.0).all() and (ev["target_reference"] == "source").all()
    assert (ev["dataset_target_return"] == float(load_manifest(data_dir).returns.max())).all()
    for col in ("episode_reward", "episode_reward_dataset_target"):
        assert ev[col].abs().min() > 0, col  # cheetah_run: dense reward
    assert np.allclose(ev["normalized_score"], 100 * ev["episode_reward"] / 200.0)
    assert np.allclose(ev["normalized_score_dataset_target"], 100 * ev["episode_reward_dataset_target"] / 200.0)
    tr = pd.read_csv(run / "train.csv")
    assert list(tr["update"]) == [2, 4] and tr["dt_loss"].notna().all()
    ckpt = torch.load(run / "checkpoint.pt", weights_only=True)
    assert ckpt["offline"]["update"] == 4 and set(ckpt["agent"]) == {"model"}
    assert ckpt["learner"]["sampler"]["rng"] == ckpt["replay_rng"]


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_the_update_on_cuda_makes_no_host_sync_and_matches_the_cpu_update():
    """The whole DT update on a GPU under torch's sync debug mode: neither the loss (gathered by the sampler's
    ``keep``, not indexed by the boolean mask) nor the batch's copies (pinned, non-blocking) wait for the device."""
    sampler_batch = _dt().make_sampler(_episodes(), seed=0).sample(6)
    assert SMALL["agent.dt.dropout"] == 0.0  # the same function on both devices (their RNGs differ)
    rc = typed(compose(["agent=dt", "profile=tiny", "task=hopper_hop"] + [f"{k}={v}" for k, v in SMALL.items()]))
    results = {}
    for device in ("cpu", "cuda"):
        torch.manual_seed(0)
        learner = build_learner(rc.agent, OBS, A_DIM, device)
        learner.update(sampler_batch, 0)  # the first update: lazy CUDA initialisation may synchronize
        torch.cuda.synchronize()
        torch.cuda.set_sync_debug_mode("error" if device == "cuda" else "default")
        try:
            metrics = learner.update(sampler_batch, 1)
        finally:
            torch.cuda.set_sync_debug_mode("default")
        results[device] = {k: float(v) for k, v in metrics.items()}
    assert results["cuda"] == pytest.approx(results["cpu"], rel=1e-2, abs=1e-4)  # cuDNN may use TF32
