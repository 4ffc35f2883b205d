"""Issue 24: a run is what its learner reads, its budget extends, and its files migrate.

Online and offline extensions are compared with runs trained to the larger budget in one go, in this process (bit for
bit: one machine, one process); the format-1 fixture (tests/data/v1_runs, written by the code before this change) is
copied, loaded, resumed and extended.
"""

from __future__ import annotations

import copy
import json
import os
import shutil
from pathlib import Path

import pandas as pd
import pytest
import yaml
from omegaconf import OmegaConf
from typer.testing import CliRunner

os.environ.setdefault("MUJOCO_GL", "egl")

from analysis.load import load_results  # noqa: E402
from analysis.scores import final_scores, learning_curves  # noqa: E402
from helpers import assert_wandb_mirrors_csv, launch_app, write_sweep  # noqa: E402
from offline_fixtures import write_dataset  # noqa: E402
from repro.config.compose import ConfigError, compose, compose_base, run_keys  # noqa: E402
from repro.config.schema import learner_sections, unread_keys  # noqa: E402
from repro.launch.spec import load_file  # noqa: E402
from repro.launch.spec.sharing import shared_frames  # noqa: E402
from repro.runs import migrate, rundir  # noqa: E402
from repro.runs.runformat import EVAL, META, TRAIN, run_state  # noqa: E402
from repro.train import api  # noqa: E402

FIXTURE = Path(__file__).parent / "data" / "v1_runs"
FIXTURE_RUN = Path("fixture/taco/base/cheetah_run/seed_1")
# The fixture's own command (tests/data/v1_runs/README.md): small networks and 32-pixel frames.
SMALL = ["profile=tiny", "env.image_size=32", "agent.feature_dim=16", "agent.hidden_dim=16",
         "agent.action_hidden_dim=16", "train.save_frames=false", "runtime.threads=1"]
WALL = ("total_time", "fps", "updates_per_s")
ONLINE_GROUP = pytest.mark.xdist_group("budgets_online")  # the tests of the module-scoped ``online`` runs: one worker


# The extension tests' runs: SMALL with 50-frame episodes, updates from frame 50, evaluations every 100 frames.
FAST = [*SMALL, "env.max_episode_frames=50", "train.seed_frames=50", "train.eval_every_frames=100"]


def _train(root: Path, *extra: str) -> tuple[Path, list[str]]:
    said: list[str] = []
    path = api.train([*FAST, "experiment=budgets", f"runtime.results_root={root}", *extra], echo=said.append)
    return path, said


def _csv(path: Path) -> pd.DataFrame:
    df = pd.read_csv(path)
    return df.drop(columns=[c for c in WALL if c in df.columns])


# ------------------------------------------------------------------------------------------ online extension
@pytest.fixture(scope="module")
def online(tmp_path_factory) -> dict[str, object]:
    """A run trained to 170 frames (mid-episode: 50-frame episodes, evaluations every 100) and extended to 200, and
    the same run trained to 200 in one go."""
    ext, one = tmp_path_factory.mktemp("extended"), tmp_path_factory.mktemp("one_go")
    short, said_short = _train(ext, "train.frames=170")
    before = {f: (short / f).read_bytes() for f in (EVAL, TRAIN)}
    extended, said_ext = _train(ext, "train.frames=200")
    again, said_again = _train(ext, "train.frames=180")
    whole, _ = _train(one, "train.frames=200")
    return {"short": short, "before": before, "extended": extended, "whole": whole, "said_short": said_short,
            "said_ext": said_ext, "said_again": said_again, "again": again, "root": ext, "one_root": one}


@pytest.mark.slow
@ONLINE_GROUP
def test_an_extension_equals_a_run_trained_to_the_larger_budget_in_one_go(online):
    ext, whole = Path(online["extended"]), Path(online["whole"])
    assert ext == online["short"] == online["again"]
    assert any(line.startswith("extending from 170 to 200 frames") for line in online["said_ext"]), online["said_ext"]
    pd.testing.assert_frame_equal(_csv(ext / TRAIN), _csv(whole / TRAIN))  # the training trajectory: unchanged
    e, w = _csv(ext / EVAL), _csv(whole / EVAL)
    assert list(e["frame"]) == [0, 100, 170, 200] and list(w["frame"]) == [0, 100, 200]
    pd.testing.assert_frame_equal(e[e["frame"] != 170].reset_index(drop=True), w)
    # the short budget's final evaluation is kept, unchanged (re-evaluated on the way, as when the run stopped there)
    short_eval = pd.read_csv(pd.io.common.BytesIO(online["before"][EVAL])).drop(columns=["total_time"])
    pd.testing.assert_frame_equal(e.iloc[:3].reset_index(drop=True), short_eval)
    meta = json.loads((ext / META).read_text())
    assert [b["budget"] for b in meta["budgets"]] == [170, 200] and meta["format"] == migrate.META_FORMAT
    assert [(x["from"], x["to"]) for x in meta["extensions"]] == [(170, 200)]
    assert yaml.safe_load((ext / rundir.CONFIG).read_text())["train"]["frames"] == 200


@pytest.mark.slow
@ONLINE_GROUP
def test_a_smaller_or_equal_budget_on_a_done_run_is_a_no_op_in_one_line(online):
    assert online["said_again"] == [f"already done: {online['extended']} (trained to 200 frames; train.frames=180 "
                                    "asks no more)"]
    assert run_state(online["extended"], 170) == run_state(online["extended"], 200) == "done"
    assert run_state(online["extended"], 201) == "partial"


@pytest.mark.slow
@ONLINE_GROUP
def test_analysis_marks_the_budget_end_row_and_reads_each_budget_s_prefix(online):
    res = load_results(online["root"])
    ev = res.eval.sort_values("frame")
    assert list(ev.loc[ev["budget_end"], "frame"]) == [170]
    whole = load_results(online["one_root"])
    # at 200 the extended run scores as the one-go run; at 170 it scores its own row at 170; curves skip that row
    for budget in (200, 180):
        a, b = final_scores(res, budget), final_scores(whole, budget)
        assert (a["score"].tolist(), a["frame"].tolist()) == (b["score"].tolist(), b["frame"].tolist())
    assert final_scores(res, 170)["frame"].tolist() == [170.0]
    assert learning_curves(res)["value"].tolist() == learning_curves(whole)["value"].tolist()


@pytest.mark.slow
@ONLINE_GROUP
def test_a_changed_default_of_an_unread_section_leaves_the_run_resumable_and_done(online):
    """The issue's probe: cql.n_samples 10 -> 11 refused an online TACO run; an online run does not read agent.cql."""
    cfg = compose([*FAST, "experiment=budgets", f"runtime.results_root={online['root']}", "train.frames=200",
                   "++agent.cql.n_samples=11", "++agent.iql.expectile=0.9", "++agent.dt.n_layers=5",
                   "offline.eval_episodes=3"])
    assert rundir.config_diff(online["extended"], cfg) == []
    said: list[str] = []
    assert api.train_config(cfg, echo=said.append) == online["extended"] and said[0].startswith("already done")
    saved = yaml.safe_load((Path(online["extended"]) / rundir.CONFIG).read_text())
    assert "offline" not in saved and not {"cql", "iql", "dt", "td3bc"} & set(saved["agent"])


@pytest.mark.slow
@ONLINE_GROUP
def test_a_changed_key_the_run_reads_is_still_refused(online):
    before = {p.name: p.read_bytes() for p in Path(online["extended"]).iterdir() if p.is_file()}
    with pytest.raises(rundir.RunDirMismatch, match=r"agent\.lr: 0\.0001 -> 0\.0002"):
        _train(online["root"], "train.frames=200", "agent.lr=0.0002")
    assert {p.name: p.read_bytes() for p in Path(online["extended"]).iterdir() if p.is_file()} == before


def test_each_offline_learner_reads_only_its_own_section_and_the_online_agent_none():
    assert [learner_sections(n) for n in ("actor_critic", "bc", "cql")] == [(), ("offline",), ("agent.cql", "offline")]
    online = compose(["agent=taco"])
    data = rundir.run_keys(online)
    assert "offline" not in data and not {"cql", "td3bc", "iql", "dt"} & set(data["agent"])
    for agent, own in (("cql", "cql"), ("td3bc", "td3bc"), ("iql", "iql"), ("dt", "dt"), ("bc", None)):
        data = rundir.run_keys(compose([f"agent={agent}", "offline.dataset=medium"]))
        assert {"cql", "td3bc", "iql", "dt"} & set(data["agent"]) == ({own} if own else set()), agent
        assert "offline" in data and "frames" not in data["train"] and "capacity" not in data["replay"]
    offline = compose(["agent=cql", "offline.dataset=medium"])
    changed = compose(["agent=cql", "offline.dataset=medium", "agent.cql.n_samples=11"])
    other = compose(["agent=cql", "offline.dataset=medium", "++agent.iql.expectile=0.9", "train.seed_frames=7"])
    from repro.config.compose import identity

    assert identity(offline) == identity(other) != identity(changed)
    assert "agent.cql" in unread_keys("actor_critic") and "agent.cql" not in unread_keys("cql")


def test_profile_tiny_makes_an_offline_run_tiny_too():
    """profile=tiny is CI-sized for offline learners as for online ones: a few updates, evaluated and saved within
    them (without it, an offline run under profile=tiny trained the default 100,000 updates)."""
    tiny = compose(["agent=td3bc", "task=cheetah_run", "profile=tiny", "offline.dataset=medium"]).offline
    full = compose(["agent=td3bc", "task=cheetah_run", "offline.dataset=medium"]).offline
    assert tiny.updates <= 100 < full.updates
    assert tiny.eval_episodes == 1
    for key in ("eval_every_updates", "checkpoint_every_updates", "log_every_updates"):
        assert tiny[key] <= tiny.updates, key


# ------------------------------------------------------------------------------------------ offline extension
OFFLINE = ["agent=td3bc", "task=cheetah_run", "profile=tiny", "env.image_size=32", "agent.feature_dim=16",
           "agent.hidden_dim=16", "runtime.threads=1", "offline.dataset=medium", "offline.eval_every_updates=3",
           "offline.eval_episodes=1", "offline.checkpoint_every_updates=3", "offline.log_every_updates=3",
           "experiment=budgets"]


@pytest.mark.slow
def test_an_offline_extension_4_to_8_updates_equals_an_8_update_run(tmp_path):
    roots = [tmp_path / "ext", tmp_path / "one"]
    for root in roots:
        write_dataset(root / "datasets" / "cheetah_run" / "medium", task="cheetah_run", action_dim=6,
                      frame_shape=(3, 32, 32), best_return=200.0)
    said: list[str] = []
    run = api.train([*OFFLINE, f"runtime.results_root={roots[0]}", "offline.updates=4"], echo=said.append)
    api.train([*OFFLINE, f"runtime.results_root={roots[0]}", "offline.updates=8"], echo=said.append)
    whole = api.train([*OFFLINE, f"runtime.results_root={roots[1]}", "offline.updates=8"], echo=lambda s: None)
    assert any(s.startswith("extending from 4 to 8 updates") for s in said), said
    for name in (TRAIN, EVAL):
        e, w = _csv(run / name), _csv(whole / name)
        assert 4 in set(e["update"]) and 4 not in set(w["update"])
        pd.testing.assert_frame_equal(e[e["update"] != 4].reset_index(drop=True), w)  # the row at 6 sums 4..6
    res = load_results(roots[0])
    assert list(res.eval.loc[res.eval["budget_end"], "update"]) == [4]


# ------------------------------------------------------------------------------------------ formats that migrate
def _fixture(tmp_path: Path) -> Path:
    root = tmp_path / "v1"
    shutil.copytree(FIXTURE, root)
    return root


def test_the_v1_fixture_loads_and_migrates_to_what_today_writes(tmp_path):
    root = _fixture(tmp_path)
    run = root / FIXTURE_RUN
    raw = yaml.safe_load((run / rundir.CONFIG).read_text())
    assert "format" not in raw and "cql" in raw["agent"]  # format 1 as committed
    migrated = migrate.migrate_config(raw)
    fresh = yaml.safe_load(rundir.config_text(compose(
        [*SMALL[:-1], "train.frames=200", "experiment=fixture", "runtime.results_root=/tmp/fx"])))
    migrated.pop("runtime"), fresh.pop("runtime")  # runtime keys added since are no part of a run
    assert migrated == fresh
    meta = migrate.migrate_meta(json.loads((run / META).read_text()), rundir.read_done(run))
    assert meta["format"] == 2 and meta["budgets"][0]["budget"] == 200 and meta["extensions"] == []
    res = load_results(root)
    assert res.runs.iloc[0]["status"] == "done" and list(res.eval["frame"]) == [0, 200]
    assert not res.eval["budget_end"].any()


@pytest.mark.slow
def test_the_v1_fixture_resumes_and_extends(tmp_path):
    root = _fixture(tmp_path)
    run = root / FIXTURE_RUN
    args = [*SMALL, "experiment=fixture", f"runtime.results_root={root}"]
    said: list[str] = []
    assert api.train([*args, "train.frames=200"], echo=said.append) == run
    assert said[0].startswith("already done") and "format" not in (run / rundir.CONFIG).read_text()  # untouched
    prefix = {f: (run / f).read_text().splitlines()[:3] for f in (EVAL, TRAIN)}
    api.train([*args, "train.frames=400"], echo=said.append)
    assert any(s.startswith("extending from 200 to 400 frames") for s in said), said
    assert yaml.safe_load((run / rundir.CONFIG).read_text())["format"] == migrate.CONFIG_FORMAT
    ev, tr = pd.read_csv(run / EVAL), pd.read_csv(run / TRAIN)
    assert list(ev["frame"]) == [0, 200, 400] and list(tr["frame"]) == [100, 200, 300, 400]
    # the rows before the checkpoint stay as the old code wrote them, byte for byte, their cells moved under today's
    # header (columns added since, e.g. the actor's health of issue 49, empty); the frame-200 evaluation comes after it
    # and is re-run from the fixture's weights, on this machine's CPU: equal within float tolerance (a CPU of other
    # features gives other last bits), its wall-clock total_time aside
    old_header = prefix[TRAIN][0].split(",")
    header = (run / TRAIN).read_text().splitlines()[0].split(",")
    assert set(old_header) < set(header) and set(header) - set(old_header) == {"actor_saturated", "actor_pretanh"}
    assert [dict(zip(header, line.split(","))) for line in (run / TRAIN).read_text().splitlines()[1:3]] == [
        {**dict.fromkeys(header, ""), **dict(zip(old_header, line.split(",")))} for line in prefix[TRAIN][1:]]
    assert (run / EVAL).read_text().splitlines()[:2] == prefix[EVAL][:2]
    old_row = pd.read_csv(pd.io.common.StringIO("\n".join(prefix[EVAL]) + "\n")).iloc[1]
    new_row = ev.iloc[1]
    for col in ("frame", "step", "episode", "episode_length", "eval_episodes"):
        assert new_row[col] == old_row[col], col
    assert new_row["episode_reward"] == pytest.approx(old_row["episode_reward"], rel=1e-4, abs=1e-6)
    meta = json.loads((run / META).read_text())
    assert [m["file"] for m in meta["migrations"]] == [META, rundir.CONFIG]
    assert rundir.read_done(run)["frame"] == 400 and load_results(root).runs.iloc[0]["last_frame"] == 400


def test_every_key_of_todays_config_is_in_the_current_format_or_has_a_migration():
    """A key added to the packaged YAML without a new format version (and its migration step) fails here: format-1
    files would take no value for it, and format-2 files written before it would be refused."""
    base = OmegaConf.to_container(compose_base(), resolve=True, enum_to_str=True)
    base.pop("runtime")
    assert migrate.CONFIG_FORMAT == max(migrate.CONFIG_STEPS) + 1
    assert sorted(migrate._leaves(base)) == sorted(migrate._leaves(migrate.current_defaults()))


def test_a_v1_file_behaves_as_its_old_behaviour_for_the_learners_that_had_it():
    raw = OmegaConf.to_container(compose(["agent=cql", "offline.dataset=medium"]), resolve=True, enum_to_str=True)
    raw["agent"]["dt"] = dict(migrate.v2_defaults()["agent"]["dt"])  # a version-1 file held every learner's section
    del raw["agent"]["cql"]["clip_policy_samples"], raw["agent"]["dt"]["init"], raw["train"]["eval_episodes"]
    out = migrate.migrate_config(raw)
    assert out["format"] == migrate.CONFIG_FORMAT and out["agent"]["cql"]["clip_policy_samples"] is False  # CQL's old
    assert out["agent"]["fast"] is False  # the 2 -> 3 step: runs before agent.fast ran the plain path
    assert "dt" not in out["agent"] and "eval_episodes" not in out["train"]  # not read by CQL: dropped
    with pytest.raises(migrate.FormatError, match=f"format {migrate.CONFIG_FORMAT + 1}"):
        migrate.migrate_config({"format": migrate.CONFIG_FORMAT + 1})
    assert [str(d) for d in migrate.diff({"a": {"b": 1}}, {"a": {"b": 2, "c": 3}})] == \
        ["a.b: 1 -> 2", "a.c: <absent> -> 3"]


@pytest.mark.parametrize("overrides, sections", [
    (["agent=taco"], []), (["agent=cql", "offline.dataset=medium"], ["cql"]),
    (["agent=dt", "offline.dataset=medium"], ["dt"]), (["agent=td3bc_taco", "offline.dataset=medium"], ["td3bc"])])
def test_a_format_3_file_keeps_its_identity_in_format_4(overrides, sections):
    """Format 3 -> 4 (issue 35: a learner's section is composed by its own agent files only): a file written by the
    version before, which held its learner's section only, reads as today's config of the same command, its
    identity unchanged; each run holds its own learner's section and no other."""
    today = run_keys(compose(overrides))
    out = migrate.migrate_config({**copy.deepcopy(today), "format": 3})
    assert out == {**today, "format": 4}
    assert [k for k in ("cql", "td3bc", "iql", "dt") if k in out["agent"]] == sections


# ------------------------------------------------------------------------------------------ sweeps share runs
@pytest.mark.slow
def test_a_sweep_extending_another_trains_every_frame_once(tmp_path):
    """Two sweeps of one experiment, 100 then 200 frames, two seeds, mirrored to W&B: one run directory per run,
    each extended once (every frame trained once), and one W&B run per run that the extension continues."""
    small = [o for o in SMALL if o != "profile=tiny" and o != "runtime.threads=1"]
    short = write_sweep(tmp_path, "share_a", ["cheetah_run"], {"base": small}, seeds=2, frames=100)
    data = yaml.safe_load(short.read_text())
    longer = tmp_path / "share_b.yaml"
    longer.write_text(yaml.safe_dump({**data, "name": "share_b", "common": [*data["common"][:-1], "train.frames=200"]}))
    specs = [load_file(short), load_file(longer)]
    shared = shared_frames(specs)
    assert (shared["share_a"].to_train, shared["share_b"].to_train, shared["share_b"].total) == (200, 200, 400)
    runner, app, root = CliRunner(), launch_app(), tmp_path / "runs"
    ids = {}
    for path in (short, longer):
        out = runner.invoke(app, ["sweep", str(path), "--results-root", str(root), "--set", "runtime.wandb=true"])
        assert out.exit_code == 0, out.output
        ids[path.stem] = {p.parent.name: (p.parent / "wandb" / "run_id").read_text() for p in root.rglob(rundir.CONFIG)}
    runs = sorted(p.parent for p in root.rglob(rundir.CONFIG))
    assert [r.name for r in runs] == ["seed_1", "seed_2"], runs
    assert ids["share_a"] == ids["share_b"] and len(set(ids["share_a"].values())) == 2  # the extension: same W&B run
    for run in runs:
        meta = json.loads((run / META).read_text())
        assert [(x["from"], x["to"]) for x in meta["extensions"]] == [(100, 200)] and meta["resumes"]
        frames = pd.read_csv(run / TRAIN)["frame"]
        assert frames.is_unique and frames.is_monotonic_increasing and frames.iloc[-1] == 200
        record, _ = assert_wandb_mirrors_csv(run)  # each frame once in W&B too, across the extension
        rel = os.path.relpath(run, root)
        assert (record["name"], record["group"]) == (rel, os.path.dirname(rel))
        assert record["tags"] == ["sweep=share_b", f"seed={run.name[-1]}"]
    status = runner.invoke(app, ["status", "share_a", "--results-root", str(root)])
    assert status.exit_code == 0 and "2 done" in status.output, status.output


# ------------------------------------------------------------------------------------------ bad input
@pytest.mark.parametrize("overrides, message", [
    (["agent.lr=-1"], "agent.lr must be > 0.0 (got -1.0)."),
    (["agent.latent_action_dim=0"], "agent.latent_action_dim must be >= 1 (got 0)."),
    (["agent=dt", "agent.dt.weight_decay=-0.5"], "agent.dt.weight_decay must be >= 0.0 (got -0.5)."),
])
def test_out_of_range_values_are_one_line_before_anything_is_written(tmp_path, overrides, message):
    with pytest.raises(ConfigError) as err:
        compose([*overrides, f"runtime.results_root={tmp_path}"])
    assert str(err.value) == message and not any(tmp_path.iterdir())


def test_a_failure_before_the_first_checkpoint_leaves_no_run_directory(tmp_path, monkeypatch):
    def broken(*args, **kwargs):
        raise RuntimeError("the optimizer refused a value")

    monkeypatch.setattr(api, "build_run_learner", broken)
    with pytest.raises(RuntimeError):
        _train(tmp_path, "train.frames=200")
    assert not list(tmp_path.rglob(rundir.CONFIG)) and not list(tmp_path.rglob("seed_1"))


def test_status_of_a_missing_results_root_is_one_line_and_exit_2(tmp_path):
    out = CliRunner().invoke(launch_app(), ["status", "tiny", "--results", str(tmp_path / "missing")])
    assert out.exit_code == 2 and "does not exist" in out.output and "Traceback" not in out.output


def test_a_dataset_made_from_a_v1_run_is_still_found_by_the_same_request():
    """`repro dataset make` finds a dataset it made before: the manifest of one made from a format-1 run records the
    run's hash of that time (every section), which counts as the same source; any other hash does not."""
    from repro.train.make_dataset import _legacy_hash, _same_request, config_hash

    run = FIXTURE / FIXTURE_RUN
    legacy = _legacy_hash(run)
    current = config_hash(rundir.saved_identity(run) or {})
    assert legacy is not None and legacy != current
    fields = {"task": "cheetah_run", "kind": "medium", "source": {"run_dir": str(run), "config_hash": current},
              "rule": {"kind": "medium", "transitions": 10, "seed": 0}}
    old = {**fields, "source": {**fields["source"], "config_hash": legacy}}
    assert _same_request(fields, fields) and _same_request(old, fields, legacy)
    assert not _same_request(old, fields) and not _same_request({**old, "source": {"config_hash": "x"}}, fields, legacy)


def test_a_format_2_file_migrates_to_todays_config_with_the_plain_path():
    """config format 3 added agent.fast: a format-2 run (written before it) ran the plain path, so it migrates to
    exactly today's config of the same overrides, and a resume or extension finds no difference in identity."""
    today = yaml.safe_load(rundir.config_text(compose(["profile=tiny", "runtime.results_root=/tmp/fx"])))
    old = copy.deepcopy(today)
    del old["agent"]["fast"]
    old["format"] = 2
    assert migrate.migrate_config(old) == today
    old["agent"]["fast"] = True  # a value already there is kept
    assert migrate.migrate_config(old)["agent"]["fast"] is True
