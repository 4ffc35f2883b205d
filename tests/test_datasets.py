"""Offline datasets: the on-disk format, resumable writes, V-D4RL / DrQ-v2 import and export, the CLI.

The external files are written here, by hand, from a synthetic environment whose frame encodes the state
and whose reward is a known function of (state, action taken from that state): any off-by-one between
frames, actions and rewards on import breaks :func:`assert_aligned`.
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from typer.testing import CliRunner

from repro.data.cli import dataset_app
from repro.data.dataset import (
    DatasetError,
    check_dataset,
    iter_episodes,
    load_manifest,
    open_dataset,
    resolve_dataset,
    write_dataset,
)

TASK, A = "hopper_hop", 4  # hopper_hop's action dim
LENGTHS = (5, 8, 6)  # transitions per episode: never assume 500
runner = CliRunner()


# ------------------------------------------------------------------ synthetic environment
def reward_fn(s: np.ndarray, a: np.ndarray) -> np.ndarray:
    return (a[..., 0] * (1 + s % 5) + 0.01 * s).astype(np.float32)


def next_state(s: np.ndarray, a: np.ndarray) -> np.ndarray:
    return (s + 1 + 3 * (a[..., 1] > 0)) % 200


def encode(states: np.ndarray, size: int = 84) -> np.ndarray:
    """(N,) states -> (N, 3, size, size) uint8 frames, constant per channel (survive bicubic resizing)."""
    vals = (states[:, None] + 20 * np.arange(3)[None, :]) % 256
    return np.broadcast_to(vals[:, :, None, None], (len(states), 3, size, size)).astype(np.uint8)


def decode(frames: np.ndarray) -> np.ndarray:
    return frames[:, 0, frames.shape[2] // 2, frames.shape[3] // 2].astype(np.int64)


def rollout(seed: int, T: int) -> dict[str, np.ndarray]:
    """states (T+1,), actions (T, A) taken from each state, rewards (T,) = reward_fn(state, action)."""
    rng = np.random.default_rng(seed)
    s = [int(rng.integers(0, 200))]
    actions = rng.uniform(-1, 1, (T, A)).astype(np.float32)
    for t in range(T):
        s.append(int(next_state(np.array(s[-1]), actions[t])))
    states = np.array(s)
    rewards = reward_fn(states[:-1], actions)
    discounts = np.ones(T, np.float32)
    return {"states": states, "actions": actions, "rewards": rewards, "discounts": discounts}


def assert_aligned(ep: dict[str, np.ndarray]) -> None:
    s = decode(ep["frames"])
    assert len(ep["frames"]) == len(ep["actions"]) + 1 == len(ep["rewards"]) + 1
    np.testing.assert_allclose(ep["rewards"], reward_fn(s[:-1], ep["actions"]), rtol=0, atol=1e-6)
    np.testing.assert_array_equal(s[1:], next_state(s[:-1], ep["actions"]))


def truth() -> list[dict[str, np.ndarray]]:
    return [rollout(seed, T) for seed, T in enumerate(LENGTHS)]


def dm_rows(r: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """dm_env rows: row t holds the action that led to state t and the reward received on arriving."""
    action = np.concatenate([np.zeros((1, A), np.float32), r["actions"]])
    reward = np.concatenate([[0.0], r["rewards"]]).astype(np.float32)
    discount = np.concatenate([[1.0], r["discounts"]]).astype(np.float32)
    return action, reward, discount


# ------------------------------------------------------------------ external layouts, written by hand
def write_vd4rl84(path: Path, rolls: list[dict], last_step_type: int = 2) -> Path:
    cols: dict[str, list] = {"observation": [], "action": [], "reward": [], "discount": [], "step_type": []}
    for r in rolls:
        action, reward, discount = dm_rows(r)
        st = np.ones(len(action))
        st[0], st[-1] = 0, 2
        for k, v in zip(cols, (encode(r["states"]), action, reward, discount, st)):
            cols[k].append(v)
    cols["step_type"][-1][-1] = last_step_type
    path.parent.mkdir(parents=True, exist_ok=True)
    with h5py.File(path, "w") as h:
        for k, v in cols.items():
            h.create_dataset(k, data=np.concatenate(v), compression="gzip")
    return path


def write_vd4rl64(folder: Path, rolls: list[dict]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for i, r in enumerate(rolls):
        action, reward, discount = dm_rows(r)
        n = len(action)
        first, last = np.zeros(n, bool), np.zeros(n, bool)
        first[0], last[-1] = True, True
        np.savez_compressed(folder / f"20220301T0000{i:02d}-{i:032x}-{n}.npz",
                            image=encode(r["states"], 64).transpose(0, 2, 3, 1), action=action, reward=reward,
                            discount=discount, is_first=first, is_last=last, is_terminal=np.zeros(n, bool))
    return folder


def write_drqv2(folder: Path, rolls: list[dict]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for i, r in enumerate(rolls):
        action, reward, discount = dm_rows(r)
        f = encode(r["states"])
        prev = [f[max(t - 2, 0)] for t in range(len(f))], [f[max(t - 1, 0)] for t in range(len(f))]
        obs = np.concatenate([np.stack(prev[0]), np.stack(prev[1]), f], axis=1)  # newest frame last
        # names sort by time stamp, which is not the index order 10, 9, 11: the importer must use the index
        np.savez_compressed(folder / f"20230101T1200{i:02d}_{[10, 9, 11][i]}_{len(f) - 1}.npz",
                            observation=obs, action=action, reward=reward[:, None], discount=discount[:, None])
    return folder


WRITERS = {"vd4rl-84": lambda d, rolls: write_vd4rl84(d / "data.hdf5", rolls).parent,
           "vd4rl-64": lambda d, rolls: write_vd4rl64(d, rolls),
           "drqv2": lambda d, rolls: write_drqv2(d, rolls)}
DRQ_ORDER = [1, 0, 2]  # file indices 10, 9, 11: episode order is by index


def ordered(fmt: str, rolls: list[dict]) -> list[dict]:
    return [rolls[i] for i in DRQ_ORDER] if fmt == "drqv2" else rolls


def invoke(*args: str):
    result = runner.invoke(dataset_app, [str(a) for a in args], terminal_width=200)
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    return result


def assert_one_line_error(result, needle: str) -> None:
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    assert needle in lines[0], lines[0]


def import_(tmp_path: Path, fmt: str, src: Path, name: str = "ds") -> Path:
    out = tmp_path / "datasets" / name
    result = invoke("import", src, "--format", fmt, "--task", TASK, "--out", out)
    assert result.exit_code == 0, result.output
    return out


# ------------------------------------------------------------------ import: alignment, counts, returns
@pytest.mark.parametrize("fmt", list(WRITERS))
def test_import_pairs_each_frame_with_the_action_taken_from_it(tmp_path, fmt):
    rolls = truth()
    src = WRITERS[fmt](tmp_path / "src", rolls)
    out = import_(tmp_path, fmt, src)
    assert check_dataset(out) == []
    m = load_manifest(out)
    assert (m.task, m.kind, m.action_dim, m.frame_shape) == (TASK, "imported", A, (3, 84, 84))
    want = ordered(fmt, rolls)
    assert [e.transitions for e in m.episodes] == [len(r["actions"]) for r in want]
    assert m.transitions == sum(LENGTHS)
    eps = list(iter_episodes(out))
    for ep, r in zip(eps, want, strict=True):
        assert_aligned(ep)
        np.testing.assert_array_equal(decode(ep["frames"]), r["states"])
        np.testing.assert_array_equal(ep["actions"], r["actions"])
    # per-episode returns equal the environment's, in the manifest and in the files
    np.testing.assert_allclose(m.returns, [r["rewards"].astype(np.float64).sum() for r in want], atol=1e-9)


def test_a_shifted_action_column_is_caught_by_the_alignment_check():
    """The check itself can fail: pairing frame t with the action that led to it (TorchRL's slip)."""
    r = rollout(0, 6)
    action, reward, _ = dm_rows(r)
    bad = {"frames": encode(r["states"]), "actions": action[:-1], "rewards": reward[1:]}
    with pytest.raises(AssertionError):
        assert_aligned(bad)
    bad = {"frames": encode(r["states"]), "actions": action[1:], "rewards": reward[:-1]}
    with pytest.raises(AssertionError):
        assert_aligned(bad)


# ------------------------------------------------------------------ export: round trips
def read_external(fmt: str, folder: Path) -> list[dict[str, np.ndarray]]:
    """The raw arrays of a folder in ``fmt``, in episode order, without going through the importers."""
    if fmt == "vd4rl-84":
        (f,) = sorted(folder.glob("*.hdf5"))
        with h5py.File(f, "r") as h:
            return [{k: h[k][:] for k in h.keys()}]
    files = sorted(folder.glob("*.npz"))
    if fmt == "drqv2":
        files.sort(key=lambda p: int(p.stem.split("_")[1]))
    out = []
    for p in files:
        with np.load(p) as z:
            out.append({k: z[k] for k in z.files})
    return out


@pytest.mark.parametrize("fmt", list(WRITERS))
def test_import_then_export_gives_back_the_same_arrays(tmp_path, fmt):
    src = WRITERS[fmt](tmp_path / "src", truth())
    out = import_(tmp_path, fmt, src)
    result = invoke("export", out, "--format", fmt, "--out", tmp_path / "back")
    assert result.exit_code == 0, result.output
    before, after = read_external(fmt, src), read_external(fmt, tmp_path / "back")
    assert len(before) == len(after)
    for b, a in zip(before, after):
        for k in b:
            assert k in a, k
            assert a[k].shape == b[k].shape, k
            if k == "image":  # 64 -> 84 -> 64 resizing: exact only for these constant frames
                assert np.abs(a[k].astype(int) - b[k].astype(int)).max() <= 1
            else:
                np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    # returns per episode, before and after, from the raw reward columns (row 0 of an episode is a dummy)
    assert raw_returns(fmt, before) == raw_returns(fmt, after)
    assert raw_returns(fmt, before) == pytest.approx(list(load_manifest(out).returns), abs=1e-9)


def raw_returns(fmt: str, files: list[dict[str, np.ndarray]]) -> list[float]:
    if fmt != "vd4rl-84":
        return [float(f["reward"][1:].astype(np.float64).sum()) for f in files]
    (f,) = files
    starts = list(np.flatnonzero(f["step_type"] == 0)) + [len(f["step_type"])]
    return [float(f["reward"][s + 1:e].astype(np.float64).sum()) for s, e in zip(starts, starts[1:])]


def test_converting_between_formats_keeps_every_dataset_episode(tmp_path):
    src = write_vd4rl84(tmp_path / "src" / "a.hdf5", truth()).parent
    first = import_(tmp_path, "vd4rl-84", src, "one")
    assert invoke("export", first, "--format", "drqv2", "--out", tmp_path / "drq").exit_code == 0
    second = import_(tmp_path, "drqv2", tmp_path / "drq", "two")
    for a, b in zip(iter_episodes(first), iter_episodes(second), strict=True):
        for k in ("frames", "actions", "rewards", "discounts", "ep_id"):
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    np.testing.assert_array_equal(load_manifest(first).returns, load_manifest(second).returns)


def test_hdf5_episodes_are_counted_across_several_files(tmp_path):
    rolls = truth() + [rollout(7, 3)]
    write_vd4rl84(tmp_path / "src" / "0.hdf5", rolls[:2])
    write_vd4rl84(tmp_path / "src" / "1.hdf5", rolls[2:])
    out = import_(tmp_path, "vd4rl-84", tmp_path / "src")
    m = load_manifest(out)
    assert [e.transitions for e in m.episodes] == [5, 8, 6, 3]
    for ep, r in zip(iter_episodes(out), rolls, strict=True):
        assert_aligned(ep)
        np.testing.assert_array_equal(decode(ep["frames"]), r["states"])


def test_vd4rl64_frames_are_resized_to_84_and_export_back_to_64(tmp_path):
    rng = np.random.default_rng(0)
    src = write_vd4rl64(tmp_path / "src", truth()[:1])
    (f,) = src.glob("*.npz")
    with np.load(f) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["image"] = rng.integers(0, 256, arrays["image"].shape, dtype=np.uint8)  # not constant
    np.savez_compressed(f, **arrays)
    out = import_(tmp_path, "vd4rl-64", src)
    (ep,) = iter_episodes(out)
    assert ep["frames"].shape[1:] == (3, 84, 84)
    assert invoke("export", out, "--format", "vd4rl-64", "--out", tmp_path / "back").exit_code == 0
    (back,) = read_external("vd4rl-64", tmp_path / "back")
    assert back["image"].shape == arrays["image"].shape and back["image"].dtype == np.uint8


# ------------------------------------------------------------------ bad inputs: one line, exit 2
def _truncate(path: Path) -> None:
    raw = path.read_bytes()
    path.write_bytes(raw[: len(raw) // 2])


BAD_CASES = {
    "hdf5 last episode cut": ("vd4rl-84", lambda d: write_vd4rl84(d / "x.hdf5", truth(), last_step_type=1).parent,
                              "truncated"),
    "hdf5 file cut": ("vd4rl-84", lambda d: (_truncate(write_vd4rl84(d / "x.hdf5", truth())), d)[1], "corrupt"),
    "hdf5 garbage": ("vd4rl-84", lambda d: ((d / "x.hdf5").write_bytes(b"not hdf5" * 100), d)[1], "corrupt"),
    "hdf5 no step_type": ("vd4rl-84", lambda d: _drop_dataset(write_vd4rl84(d / "x.hdf5", truth()), "step_type"),
                          "step_type"),
    "npz given as hdf5": ("vd4rl-84", lambda d: write_drqv2(d, truth()), "no *.hdf5"),
    "npz file cut": ("vd4rl-64", lambda d: (_truncate(sorted(write_vd4rl64(d, truth()).glob("*.npz"))[1]), d)[1],
                     "corrupt or truncated"),
    "npz episode without last step": ("vd4rl-64", lambda d: _rewrite(write_vd4rl64(d, truth()), is_last=False),
                                      "truncated"),
    "npz channels first": ("vd4rl-64", lambda d: write_drqv2(d, truth()), "no array image"),
    "drqv2 wrong name": ("drqv2", lambda d: write_vd4rl64(d, truth()), "is not named"),
    "drqv2 newest frame first": ("drqv2", lambda d: _reverse_stack(write_drqv2(d, truth())), "stacked"),
    "drqv2 length in name": ("drqv2", lambda d: _rename_length(write_drqv2(d, truth())), "truncated"),
}


def _drop_dataset(path: Path, key: str) -> Path:
    with h5py.File(path, "a") as h:
        del h[key]
    return path.parent


def _rewrite(folder: Path, is_last: bool) -> Path:
    f = sorted(folder.glob("*.npz"))[-1]
    with np.load(f) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["is_last"][-1] = is_last
    np.savez_compressed(f, **arrays)
    return folder


def _reverse_stack(folder: Path) -> Path:
    for f in folder.glob("*.npz"):
        with np.load(f) as z:
            arrays = {k: z[k] for k in z.files}
        o = arrays["observation"]
        arrays["observation"] = np.concatenate([o[:, 6:9], o[:, 3:6], o[:, 0:3]], axis=1)
        np.savez_compressed(f, **arrays)
    return folder


def _rename_length(folder: Path) -> Path:
    f = sorted(folder.glob("*.npz"))[0]
    stamp, idx, n = f.stem.split("_")
    f.rename(f.with_name(f"{stamp}_{idx}_{int(n) + 1}.npz"))
    return folder


@pytest.mark.parametrize("case", list(BAD_CASES))
def test_bad_import_is_one_line_exit_2_and_writes_nothing(tmp_path, case):
    fmt, make, needle = BAD_CASES[case]
    (tmp_path / "src").mkdir()
    src = make(tmp_path / "src")
    out = tmp_path / "datasets" / "ds"
    result = invoke("import", src, "--format", fmt, "--task", TASK, "--out", out)
    assert_one_line_error(result, needle)
    assert not out.exists()


def test_another_tasks_data_or_an_unknown_task_or_format_is_refused(tmp_path):
    src = write_vd4rl84(tmp_path / "src" / "x.hdf5", truth()).parent
    out = tmp_path / "ds"
    assert_one_line_error(invoke("import", src, "--format", "vd4rl-84", "--task", "cheetah_run", "--out", out),
                          "action dim")
    assert_one_line_error(invoke("import", src, "--format", "vd4rl-84", "--task", "hoper_hop", "--out", out),
                          "hopper_hop")
    assert_one_line_error(invoke("import", src, "--format", "d4rl", "--task", TASK, "--out", out), "vd4rl-84")
    assert_one_line_error(invoke("import", tmp_path / "nothere", "--format", "drqv2", "--task", TASK, "--out", out),
                          "no such file or folder")
    assert not out.exists()


def test_existing_outputs_are_never_touched(tmp_path):
    src = write_vd4rl84(tmp_path / "src" / "x.hdf5", truth()).parent
    ds = import_(tmp_path, "vd4rl-84", src)
    # export into an existing folder
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "keep.txt").write_text("mine")
    assert_one_line_error(invoke("export", ds, "--format", "drqv2", "--out", tmp_path / "taken"), "already exists")
    assert [p.name for p in (tmp_path / "taken").iterdir()] == ["keep.txt"]
    # import into a non-empty folder that is not a dataset, or over another import
    assert_one_line_error(invoke("import", src, "--format", "vd4rl-84", "--task", TASK, "--out", tmp_path / "taken"),
                          "not a dataset")
    assert [p.name for p in (tmp_path / "taken").iterdir()] == ["keep.txt"]
    other = write_drqv2(tmp_path / "other", truth())
    manifest = (ds / "manifest.json").read_bytes()
    assert_one_line_error(invoke("import", other, "--format", "drqv2", "--task", TASK, "--out", ds),
                          "already holds a dataset")
    assert (ds / "manifest.json").read_bytes() == manifest
    # the same import again is a no-op
    result = invoke("import", src, "--format", "vd4rl-84", "--task", TASK, "--out", ds)
    assert result.exit_code == 0 and "already imported" in result.stdout
    assert (ds / "manifest.json").read_bytes() == manifest
    # export of something that is not a dataset
    assert_one_line_error(invoke("export", tmp_path / "src", "--format", "drqv2", "--out", tmp_path / "e"),
                          "no dataset")
    assert not (tmp_path / "e").exists()


def test_default_import_location_is_under_the_results_root(tmp_path):
    src = write_drqv2(tmp_path / "src", truth())
    result = invoke("import", src, "--format", "drqv2", "--task", TASK, "-r", tmp_path / "runs")
    assert result.exit_code == 0, result.output
    assert load_manifest(tmp_path / "runs/datasets" / TASK / "imported-drqv2").episodes
    assert (
        resolve_dataset("imported-drqv2", tmp_path / "runs", TASK)
        == tmp_path / "runs/datasets" / TASK / "imported-drqv2"
    )


# ------------------------------------------------------------------ the dataset format itself
def dataset_episodes(n: int = 3) -> list[dict[str, np.ndarray]]:
    out = []
    for i, r in enumerate(rollout(s, T) for s, T in zip(range(n), [4, 6, 5, 3, 7][:n])):
        out.append({"frames": encode(r["states"]), "actions": r["actions"], "rewards": r["rewards"],
                    "discounts": r["discounts"], "ep_id": np.array(100 + i)})
    return out


def write(d: Path, episodes, **kw):
    return write_dataset(d, episodes, task=TASK, kind="medium", source={"run_dir": "x"}, rule={"seed": 1}, **kw)


def test_written_dataset_reads_back_and_checks_clean(tmp_path):
    eps = dataset_episodes()
    m = write(tmp_path / "d", eps)
    assert check_dataset(tmp_path / "d") == []
    data = json.loads((tmp_path / "d/manifest.json").read_text())
    assert data["format"] == 1 and data["frame_shape"] == [3, 84, 84] and data["action_dim"] == A
    assert [e["file"] for e in data["episodes"]] == [f"episodes/ep_{i:07d}.npz" for i in range(3)]
    assert m.transitions == 15
    for i, (a, b) in enumerate(zip(eps, iter_episodes(tmp_path / "d"), strict=True)):
        assert int(b["ep_id"]) == i
        for k in ("frames", "actions", "rewards", "discounts"):
            np.testing.assert_array_equal(a[k], b[k])
    result = invoke("check", tmp_path / "d")
    assert result.exit_code == 0 and "ok" in result.stdout


@pytest.mark.parametrize("damage,needle", [
    ("flip", "sha256"),
    ("cut", "sha256"),
    ("delete", "missing"),
    ("extra", "not listed"),
    ("transitions", "transitions"),
])
def test_check_reports_each_problem_on_its_own_line(tmp_path, damage, needle):
    d = tmp_path / "d"
    write(d, dataset_episodes())
    f = d / "episodes/ep_0000001.npz"
    if damage == "flip":
        raw = bytearray(f.read_bytes())
        raw[len(raw) // 2] ^= 0xFF
        f.write_bytes(bytes(raw))
    elif damage == "cut":
        _truncate(f)
    elif damage == "delete":
        f.unlink()
    elif damage == "extra":
        (d / "episodes/ep_0000009.npz").write_bytes(f.read_bytes())
    else:
        data = json.loads((d / "manifest.json").read_text())
        data["transitions"] += 1
        (d / "manifest.json").write_text(json.dumps(data))
    problems = check_dataset(d)
    assert len(problems) == 1 and needle in problems[0], problems
    result = invoke("check", d)
    assert result.exit_code == 2
    assert result.stderr.strip().splitlines() == [f"error: {problems[0]}"]
    if damage in ("flip", "cut", "delete"):
        with pytest.raises(DatasetError):
            list(iter_episodes(d))


def test_check_finds_wrong_shapes_dtypes_and_non_finite_rewards(tmp_path):
    good = dataset_episodes(1)[0]
    for change, needle in [({"frames": good["frames"].astype(np.float32)}, "uint8"),
                           ({"actions": good["actions"][:-1]}, "actions"),
                           ({"rewards": np.where(np.arange(4) == 2, np.nan, good["rewards"]).astype(np.float32)},
                            "non-finite rewards")]:
        with pytest.raises(DatasetError, match=needle):
            write(tmp_path / f"d{len(needle)}", [{**good, **change}])
    # a file swapped for another shape behind the manifest's back (hash updated too)
    d = tmp_path / "d"
    write(d, dataset_episodes(2))
    bad = {**dataset_episodes(2)[1], "actions": np.zeros((6, A + 1), np.float32), "ep_id": np.array(1)}
    np.savez_compressed(d / "episodes/ep_0000001.npz", **bad)
    data = json.loads((d / "manifest.json").read_text())
    data["episodes"][1]["sha256"] = hashlib.sha256((d / "episodes/ep_0000001.npz").read_bytes()).hexdigest()
    (d / "manifest.json").write_text(json.dumps(data))
    (problem,) = check_dataset(d)
    assert "action dim 5" in problem


def interrupted(d: Path, episodes: list[dict], after: int) -> None:
    """A write stopped (as by Ctrl-C) when asking for episode ``after``."""
    def gen():
        for i, ep in enumerate(episodes):
            if i == after:
                raise KeyboardInterrupt
            yield ep

    with pytest.raises(KeyboardInterrupt):
        write(d, gen())


def test_a_folder_without_manifest_is_incomplete_and_a_rerun_completes_it(tmp_path):
    d = tmp_path / "d"
    interrupted(d, dataset_episodes(), after=2)
    assert sorted(p.name for p in (d / "episodes").iterdir()) == ["ep_0000000.npz", "ep_0000001.npz"]
    with pytest.raises(DatasetError, match="incomplete"):
        load_manifest(d)
    with pytest.raises(DatasetError, match="incomplete"):
        list(iter_episodes(d))
    assert "incomplete" in check_dataset(d)[0]
    assert_one_line_error(invoke("info", d), "incomplete")
    # the files on disk verify: a re-run reuses them (the callables are not called) and writes the rest
    calls = []

    def lazy(i, ep):
        def make():
            calls.append(i)
            return ep
        return make

    write(d, [lazy(i, ep) for i, ep in enumerate(dataset_episodes())])
    assert calls == [2]
    assert check_dataset(d) == []
    # a damaged file from the interrupted write is not reused
    (d / "manifest.json").unlink()
    (d / ".incomplete.json").write_text(json.dumps({"format": 1, "task": TASK, "kind": "medium",
                                                    "rule": {"seed": 1}, "source": {"run_dir": "x"}}))
    _truncate(d / "episodes/ep_0000001.npz")
    calls.clear()
    write(d, [lazy(i, ep) for i, ep in enumerate(dataset_episodes())])
    assert calls == [1] and check_dataset(d) == []


def test_partial_writes_of_other_inputs_are_refused(tmp_path):
    d = tmp_path / "d"
    interrupted(d, dataset_episodes(), after=2)
    before = {p.name: p.read_bytes() for p in (d / "episodes").iterdir()}
    with pytest.raises(DatasetError, match="other inputs"):
        write_dataset(d, dataset_episodes(), task=TASK, kind="medium-replay")
    assert {p.name: p.read_bytes() for p in (d / "episodes").iterdir()} == before


KILL_SCRIPT = """
import os, signal, sys
sys.path.insert(0, {tests!r})
from test_datasets import dataset_episodes, write
from pathlib import Path
def gen():
    for i, ep in enumerate(dataset_episodes(5)):
        if i == {kill_at}:
            os.kill(os.getpid(), signal.SIGKILL)
        yield ep
write(Path({out!r}), gen())
"""


@pytest.mark.parametrize("kill_at", [0, 3])
def test_killed_write_is_incomplete_and_a_rerun_ends_identical(tmp_path, kill_at):
    d = tmp_path / "d"
    script = KILL_SCRIPT.format(tests=str(Path(__file__).parent), kill_at=kill_at, out=str(d))
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(Path(__file__).parents[1]), os.environ.get("PYTHONPATH", "")]),
    }
    proc = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    assert len(list((d / "episodes").glob("ep_*.npz"))) == kill_at
    assert check_dataset(d) and "incomplete" in check_dataset(d)[0]
    write(d, dataset_episodes(5))
    assert check_dataset(d) == []
    ref = tmp_path / "ref"
    write(ref, dataset_episodes(5))
    a, b = load_manifest(d), load_manifest(ref)
    assert [(e.file, e.transitions, e.return_) for e in a.episodes] == [(e.file, e.transitions, e.return_)
                                                                        for e in b.episodes]
    assert not (d / ".incomplete.json").exists()


def test_resolve_and_open_refuse_unknown_other_task_and_other_action_dim(tmp_path):
    root = tmp_path / "runs"
    d = root / "datasets" / TASK / "medium"
    write(d, dataset_episodes(1))
    assert resolve_dataset("medium", root, TASK) == d
    assert resolve_dataset(str(d), "elsewhere", TASK) == d
    with pytest.raises(DatasetError, match="unknown dataset 'expert'.*known for hopper_hop: medium"):
        resolve_dataset("expert", root, TASK)
    with pytest.raises(DatasetError, match="no folder"):
        resolve_dataset(str(tmp_path / "nope"), root, TASK)
    with pytest.raises(DatasetError, match="unknown dataset"):
        resolve_dataset("medium", root, "cheetah_run")
    (root / "datasets/cheetah_run").mkdir(parents=True)
    os.symlink(d, root / "datasets/cheetah_run/medium")
    with pytest.raises(DatasetError, match="for task hopper_hop, not cheetah_run"):
        open_dataset("medium", root, "cheetah_run")
    with pytest.raises(DatasetError, match="action dim 4, the run needs 6"):
        open_dataset("medium", root, TASK, action_dim=6)
    assert open_dataset("medium", root, TASK, action_dim=4)[1].task == TASK


def test_info_prints_counts_and_per_episode_returns_and_writes_a_histogram(tmp_path):
    d = tmp_path / "d"
    m = write(d, dataset_episodes(3))
    result = invoke("info", d, "--out", tmp_path / "hist.png")
    assert result.exit_code == 0, result.output
    assert "episodes     3" in result.stdout and "transitions  15" in result.stdout
    for r in m.returns:
        assert f"{r:.2f}" in result.stdout
    assert f"mean {m.returns.mean():.2f}" in result.stdout
    assert (tmp_path / "hist.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert invoke("info", d).exit_code == 0 and (d / "returns.png").exists()
    assert check_dataset(d) == []  # the histogram beside the episodes does not disturb the dataset


def test_dataset_is_a_subcommand_of_repro():
    from repro_app.cli import app

    result = runner.invoke(app, ["dataset", "check", "/nonexistent/ds"])
    assert result.exit_code == 2
    assert result.stderr.strip() == "error: no dataset at /nonexistent/ds (not a folder)"
