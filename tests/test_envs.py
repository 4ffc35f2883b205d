"""Real-rendering tests of the pixel environments (no mocks). Needs MUJOCO_GL (egl or osmesa)."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from repro.envs import (  # noqa: E402
    TASKS,
    DistractingActionDims,
    TaskInfo,
    TimeLimit,
    UnknownTaskError,
    get_task,
    make_env,
)

DMC_TASK = "acrobot_swingup"  # cheap to render, dense reward, random initial state
MW_TASK = "hand-insert"  # the Meta-world scripted policy solves it in ~60 environment steps


def _actions(n: int, dim: int, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.uniform(-1, 1, dim).astype(np.float32) for _ in range(n)]


# ----------------------------------------------------------------------------- registry


def test_registry_table() -> None:
    assert len(TASKS) == 17  # the paper's 16 and repro verify's cartpole_balance
    assert get_task("cartpole_balance").action_dim == 1 and get_task("cartpole_balance").camera == 0
    assert get_task("quadruped_run").camera == 2 and get_task("walker_run").camera == 0
    assert get_task("reach_duplo").camera == "front_close"
    assert get_task("stick-pull").task == "stick-pull-v3"
    assert {t.suite for t in TASKS.values()} == {"dmc", "manipulation", "metaworld"}


def test_task_files_are_the_one_source_of_the_paper_settings() -> None:
    """Preset, K and nstep come from conf/task/<name>.yaml (the registry holds simulator facts only); every
    registry task has a task file of its suite and the other way round."""
    from repro.config.compose import compose, group_options

    assert set(group_options("task")) == set(TASKS)
    settings = {}
    for name, info in TASKS.items():
        cfg = compose([f"task={name}"])
        assert cfg.task.suite == info.suite, name
        settings[name] = (str(cfg.task.preset), cfg.agent.K, cfg.agent.nstep)
    assert settings["quadruped_run"] == ("medium", 1, 3) and settings["walker_run"] == ("medium", 1, 1)
    assert settings["hopper_hop"] == ("medium", 3, 3) and settings["manipulator_bring_ball"] == ("hard", 3, 3)
    assert not {f.name for f in dataclasses.fields(TaskInfo)} & {"preset", "default_K", "K", "nstep"}


def test_get_task_typo_gives_close_matches() -> None:
    with pytest.raises(UnknownTaskError) as err:
        get_task("cheetah_rnu")
    assert err.value.name == "cheetah_rnu"
    assert "cheetah_run" in err.value.close_matches
    assert "cheetah_run" in str(err.value)
    with pytest.raises(KeyError):
        get_task("hamer")


def test_import_is_lazy() -> None:
    code = (
        "import sys, repro.envs; "
        "assert 'dm_control' not in sys.modules and 'metaworld' not in sys.modules, 'eager import'"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


# ----------------------------------------------------------------------------- DMC


def test_dmc_obs_shape_dtype_and_reset_stack() -> None:
    env = make_env(DMC_TASK, seed=0, frame_stack=3, image_size=64)
    assert env.spec.obs_shape == (9, 64, 64) and env.spec.action_dim == 1
    assert not env.spec.has_success
    ts = env.reset(0)
    assert ts.first and not ts.last and ts.reward == 0.0 and ts.discount == 1.0
    assert ts.observation.shape == (9, 64, 64) and ts.observation.dtype == np.uint8
    frames = ts.observation.reshape(3, 3, 64, 64)
    assert np.array_equal(frames[0], frames[1]) and np.array_equal(frames[1], frames[2])
    assert frames.std() > 0  # a real image, not a blank
    ts = env.step(np.zeros(1, np.float32))
    assert ts.observation.shape == (9, 64, 64) and ts.observation.dtype == np.uint8
    assert not ts.first and isinstance(ts.reward, float)
    env.close()


def test_frame_stack_shifts_and_newest_frame_is_last() -> None:
    stacked = make_env(DMC_TASK, seed=0, frame_stack=3)
    single = make_env(DMC_TASK, seed=0, frame_stack=1)
    obs = [stacked.reset(3).observation]
    single_obs = [single.reset(3).observation]
    for a in _actions(3, 1):
        obs.append(stacked.step(a).observation)
        single_obs.append(single.step(a).observation)
    for prev, cur, newest in zip(obs[:-1], obs[1:], single_obs[1:]):
        assert np.array_equal(cur[:6], prev[3:])  # older frames shift towards the front
        assert np.array_equal(cur[6:], newest)  # the newest frame is the last three channels
        assert not np.array_equal(cur[6:], prev[6:])  # and it is new
    stacked.close()
    single.close()


def test_action_repeat_sums_rewards() -> None:
    rep2 = make_env(DMC_TASK, seed=0, action_repeat=2)
    rep1 = make_env(DMC_TASK, seed=0, action_repeat=1)
    assert np.array_equal(rep2.reset(5).observation, rep1.reset(5).observation)
    total = 0.0
    for a in _actions(3, 1):
        ts2 = rep2.step(a)
        first, second = rep1.step(a), rep1.step(a)
        assert ts2.reward == pytest.approx(first.reward + second.reward, rel=1e-6, abs=1e-9)
        assert np.array_equal(ts2.observation[6:], second.observation[6:])  # same state reached
        total += ts2.reward
    assert total > 0.0  # acrobot_swingup's reward is dense: the comparison is not vacuous
    rep2.close()
    rep1.close()


def test_dmc_determinism() -> None:
    env = make_env(DMC_TASK, seed=0)
    other = make_env(DMC_TASK, seed=123)  # the construction seed does not matter after reset(seed)
    first = env.reset(11).observation
    traj = [env.step(a).observation for a in _actions(2, 1)]
    assert np.array_equal(env.reset(11).observation, first)  # same env, same seed, after stepping
    assert np.array_equal(other.reset(11).observation, first)
    assert all(np.array_equal(other.step(a).observation, o) for a, o in zip(_actions(2, 1), traj))
    assert not np.array_equal(env.reset(12).observation, first)
    env.close()
    other.close()


def test_time_limit() -> None:
    env = make_env(DMC_TASK, seed=0, action_repeat=2, max_episode_frames=6)
    assert isinstance(env, TimeLimit) and env.max_agent_steps == 3
    for _ in range(2):  # two episodes: the limit resets with the episode
        env.reset(0)
        steps = [env.step(np.zeros(1, np.float32)) for _ in range(3)]
        assert [ts.last for ts in steps] == [False, False, True]
        assert steps[-1].discount == 1.0
        with pytest.raises(RuntimeError):
            env.step(np.zeros(1, np.float32))
    env.close()


def test_distracting_action_dims_are_ignored() -> None:
    env = make_env(DMC_TASK, seed=0, distracting_dims=3)
    assert isinstance(env, DistractingActionDims) and env.spec.action_dim == 4
    results = []
    for extra in (-1.0, 0.7):
        env.reset(2)
        ts = None
        for a in _actions(2, 1):
            ts = env.step(np.concatenate([a, np.full(3, extra, np.float32)]))
        assert ts is not None
        results.append((ts.observation, ts.reward))
    assert np.array_equal(results[0][0], results[1][0])
    assert results[0][1] == results[1][1]
    env.reset(2)  # the real dimension still acts: other actions in it give another state
    for a in _actions(2, 1, seed=1):
        ts = env.step(np.concatenate([a, np.full(3, -1.0, np.float32)]))
    assert not np.array_equal(ts.observation, results[0][0])
    with pytest.raises(ValueError):
        env.step(np.zeros(1, np.float32))  # the wrapped dimension alone is the wrong shape
    env.close()


def test_reach_duplo_pixels_match_the_composer_camera() -> None:
    """reach_duplo renders front_close itself; the pixels equal the environment's own observable."""
    from dm_control import manipulation

    env = make_env("reach_duplo", seed=0, frame_stack=1)
    raw = manipulation.load("reach_duplo_vision", seed=0)
    ours = env.reset(4).observation
    raw.random_state.seed(4)
    theirs = raw.reset().observation["front_close"][0]
    assert ours.shape == (3, 84, 84)
    assert np.array_equal(ours, theirs.transpose(2, 0, 1))
    env.close()
    raw.close()


# ----------------------------------------------------------------------------- Meta-world


@pytest.fixture(scope="module")
def mw_env():
    env = make_env(MW_TASK, seed=0, action_repeat=8)
    yield env
    env.close()


def test_metaworld_obs_and_determinism(mw_env) -> None:
    assert mw_env.spec.action_dim == 4 and mw_env.spec.has_success
    ts = mw_env.reset(0)
    assert ts.observation.shape == (9, 84, 84) and ts.observation.dtype == np.uint8
    frames = ts.observation.reshape(3, 3, 84, 84)
    assert np.array_equal(frames[0], frames[2])
    assert ts.info["success"] == 0.0
    assert mw_env.frames_rotated  # corner2 is defined upside down; frames are turned upright
    raw = mw_env.raw_env.render()  # the same state as rendered by Meta-world itself
    assert not np.array_equal(raw, raw[::-1, ::-1])  # not symmetric, so the check below can fail
    assert np.array_equal(frames[2], raw[::-1, ::-1].transpose(2, 0, 1))  # the observation is it turned by 180
    first, task0 = ts.observation, mw_env.task_index
    mw_env.step(np.ones(4, np.float32))
    assert np.array_equal(mw_env.reset(0).observation, first)
    seed = next(s for s in range(1, 100) if int(np.random.default_rng(s).integers(50)) != task0)
    assert not np.array_equal(mw_env.reset(seed).observation, first)


@pytest.mark.filterwarnings("ignore:Constant\\(s\\) may be too high")
def test_metaworld_success_signal(mw_env) -> None:
    """The scripted Meta-world policy solves hand-insert; info['success'] agrees with evaluate_state."""
    from metaworld.policies import SawyerHandInsertV3Policy

    policy = SawyerHandInsertV3Policy()
    mw_env.reset(1)
    successes = []
    for _ in range(25):  # ~60 environment steps needed, 200 available
        action = np.clip(policy.get_action(mw_env.state_observation), -1, 1).astype(np.float32)
        ts = mw_env.step(action)
        success = ts.info["success"]
        assert success in (0.0, 1.0)
        _, own = mw_env.raw_env.evaluate_state(mw_env.state_observation, action)
        assert float(bool(own["success"])) == success
        successes.append(success)
        if success == 1.0:
            break
    assert successes[0] == 0.0 and successes[-1] == 1.0


def test_metaworld_truncation_after_500_steps() -> None:
    env = make_env(MW_TASK, seed=0, action_repeat=125)  # 500 environment steps = 4 agent steps
    env.reset(0)
    steps = [env.step(np.zeros(4, np.float32)) for _ in range(4)]
    assert [ts.last for ts in steps] == [False, False, False, True]
    assert steps[-1].discount == 1.0
    with pytest.raises(RuntimeError):
        env.step(np.zeros(4, np.float32))
    env.reset(0)  # Meta-world needs a reset after truncation; the wrapper does it
    assert not env.step(np.zeros(4, np.float32)).last
    env.close()


# ----------------------------------------------------------------------------- every task


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(TASKS))
def test_registry_action_dim_matches_env(name: str) -> None:
    env = make_env(name, seed=0, image_size=32, frame_stack=1)
    try:
        assert env.spec.action_dim == TASKS[name].action_dim
        ts = env.reset(0)
        assert ts.observation.shape == (3, 32, 32)
        ts = env.step(np.zeros(env.spec.action_dim, np.float32))
        assert np.isfinite(ts.reward)
    finally:
        env.close()
