"""The actor's health (issue 49): the update's saturation metrics, the one rule over train.csv (repro/runs/health.py),
the warning a training run prints, `repro status`'s flag and the verify verdict's actor column."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from helpers import OBS, launch_app, make_batch, write_sweep
from repro.agent import losses
from repro.agent.agent import Agent
from repro.config.compose import compose, typed
from repro.launch import spec as specs
from repro.launch.state import record_launch, state_dir
from repro.launch.status import collect
from repro.runs import health
from repro.runs.logger import CsvLog, RunLogger


def _rows(shares: list[float], length: int = 1000) -> list[health.Row]:
    return [health.Row(frame=(i + 1) * length, length=length, share=s) for i, s in enumerate(shares)]


def test_saturation_metrics_count_entries_exactly_at_the_bound():
    pre = torch.tensor([[9.5, 0.0], [-12.0, 3.0]])  # float32 tanh(9.5) is exactly 1.0, tanh(3) is not
    m = losses.saturation_metrics(torch.tanh(pre), pre)
    assert m["actor_saturated"].item() == 0.5 and m["actor_pretanh"].item() == pytest.approx((9.5 + 12 + 3) / 4)
    near = torch.tensor([[8.0]])  # tanh(8) = 0.99999977: under the bound, gradient small but not zero
    assert losses.saturation_metrics(torch.tanh(near), near)["actor_saturated"].item() == 0.0


def test_a_real_update_logs_saturation_and_a_saturated_actor_reads_one():
    rc = typed(compose(["agent=taco", "agent.hidden_dim=32"]))
    torch.manual_seed(0)
    agent = Agent(rc.agent, OBS, 1)
    batch = make_batch(B=6, A=1)
    fresh = agent.update(batch, 5000)
    assert set(losses.SATURATION_METRICS) <= set(fresh) and set(losses.SATURATION_METRICS) <= set(agent.metric_names())
    assert fresh["actor_saturated"].item() == 0.0 and 0 < fresh["actor_pretanh"].item() < 5
    with torch.no_grad():  # the policy's last layer pushed to a pre-tanh of about -30 on every state
        agent.backbone.actor.policy[-1].bias.fill_(-30.0)
    dead = agent.update(batch, 5000)
    assert dead["actor_saturated"].item() == 1.0 and dead["actor_pretanh"].item() > 20
    # what the metric says: the actor's gradient is exactly zero, every parameter (Adam's momentum still moves it)
    grads = [p.grad for p in agent.backbone.actor.parameters()]
    assert all(g is not None and not g.any() for g in grads)


def test_the_rule_needs_a_whole_stretch_at_the_end():
    nan = math.nan
    assert health.saturation(_rows([nan] * 4 + [1.0] * 10)) is not None  # 10 episodes of 1000 frames: 10K
    found = health.saturation(_rows([nan] * 4 + [0.2] + [1.0] * 10))
    assert found is not None and found.since == 5000 and found.until == 15000 and found.frames == 10_000
    assert found.message() == "actor saturated since frame 5,000: its policy gradient is zero"
    assert health.saturation(_rows([1.0] * 9)) is None  # 9K frames: too short
    assert health.saturation(_rows([1.0] * 12 + [0.5])) is None  # recovered at the last row
    assert health.saturation(_rows([1.0] * 12 + [0.98])) is None  # 98% is not "nearly every state"
    assert health.saturation(_rows([nan] * 12)) is None  # no update yet
    broken = health.saturation(_rows([1.0] * 12 + [0.0] + [1.0] * 10))
    assert broken is not None and broken.since == 13000  # the stretch after the break, not the first one


def test_a_shorter_stretch_at_the_bound_is_said_as_what_it_is_so_far():
    nan = math.nan
    early = health.at_bound(_rows([nan] * 4 + [0.2] + [0.995] * 2))  # at the bound since the 6th episode
    assert early is not None and not early.saturated and (early.since, early.frames) == (5000, 2000)
    assert early.message() == "actor at the bound since frame 5,000: 2,000 of the 10,000 frames that make it saturated"
    assert health.saturation(_rows([nan] * 4 + [0.2] + [0.995] * 2)) is None  # the rule does not hold yet
    dead = health.at_bound(_rows([nan] * 4 + [0.2] + [1.0] * 10))
    assert dead is not None and dead.saturated and dead.message().startswith("actor saturated since frame 5,000")
    assert health.at_bound(_rows([1.0] * 3 + [0.98])) is None  # left the bound at the last row
    assert health.at_bound(_rows([nan] * 3)) is None


def test_the_watch_says_a_stretch_once_and_a_new_one_again():
    watch = health.Watch()
    said = [watch.add(r) for r in _rows([1.0] * 15 + [0.0] + [1.0] * 12)]
    frames = [s.since for s in said if s is not None]
    assert frames == [0, 16000]
    resumed = health.Watch()
    resumed.extend(_rows([1.0] * 12))  # a resume: the stretch already said is not said again
    assert resumed.add(health.Row(13000, 1000, 1.0)) is None


def test_the_online_logger_prints_one_warning_and_a_resume_does_not_repeat_it(tmp_path: Path):
    lines: list[str] = []
    names = ["actor_loss", *losses.SATURATION_METRICS]
    log = RunLogger(tmp_path, names, echo=lines.append)
    for row in _rows([math.nan] * 4 + [1.0] * 12):
        log.log_train({"frame": row.frame, "episode_length": row.length,
                       "actor_saturated": None if math.isnan(row.share) else row.share})
    offsets = log.offsets()
    log.close()
    warnings = [x for x in lines if x.startswith("warning:")]
    assert warnings == ["warning: actor saturated since frame 4,000: its policy gradient is zero (actor_saturated "
                        "1.00 over the last 10,000 frames; docs/watching.md)"]
    again: list[str] = []
    log = RunLogger(tmp_path, names, offsets=offsets, echo=again.append)
    log.log_train({"frame": 17000, "episode_length": 1000, "actor_saturated": 1.0})
    log.close()
    assert not [x for x in again if x.startswith("warning:")]
    assert health.read_at_bound(tmp_path) == health.Saturation(4000, 17000, 1.0)


def test_a_log_with_fewer_columns_is_widened_on_resume(tmp_path: Path):
    path = tmp_path / "train.csv"
    path.write_text("frame,actor_loss,taco_loss\n1000,0.5,2.0\n2000,0.25,1.5\n3000,9,9\n")
    offset = len("frame,actor_loss,taco_loss\n1000,0.5,2.0\n2000,0.25,1.5\n")  # the checkpoint's: row 3 is cut
    log = CsvLog(path, ["frame", "actor_loss", "actor_saturated", "taco_loss"], offset)
    log.write({"frame": 3000, "actor_loss": 0.125, "actor_saturated": 1.0, "taco_loss": 1.0})
    log.close()
    assert path.read_text() == ("frame,actor_loss,actor_saturated,taco_loss\n1000,0.5,,2.0\n2000,0.25,,1.5\n"
                                "3000,0.125,1.0,1.0\n")
    other = tmp_path / "other.csv"
    other.write_text("frame,bc_loss\n1000,0.5\n")
    with pytest.raises(ValueError, match="bc_loss"):  # another learner's log is refused, and left as it was
        CsvLog(other, ["frame", "actor_loss"], 100)
    assert other.read_text() == "frame,bc_loss\n1000,0.5\n"


def _train_csv(run: Path, shares: list[float]) -> None:
    run.mkdir(parents=True, exist_ok=True)
    lines = ["frame,step,episode_length,actor_saturated"]
    lines += [f"{r.frame},{r.frame // 2},{r.length},{'' if math.isnan(r.share) else r.share}" for r in _rows(shares)]
    (run / "train.csv").write_text("\n".join(lines) + "\n")
    (run / "eval.csv").write_text("frame,step,episode,episode_reward\n0,0,0,300.0\n")


def test_status_flags_a_saturated_actor(tmp_path: Path):
    sweep = write_sweep(tmp_path, "hs", ["cartpole_balance"], {"ok": [], "dead": [], "early": []}, 1)
    selection = specs.Selection(sets=(f"runtime.results_root={tmp_path}",))
    planned = specs.plan(specs.expand(specs.load(str(sweep)), selection))
    root = specs.results_root_of(planned)
    sdir = state_dir(root, "hs")
    ok, dead, early = (next(p for p in planned if f"/{v}/" in str(p.run_dir)) for v in ("ok", "dead", "early"))
    _train_csv(ok.run_dir, [math.nan] * 4 + [0.3] * 16)
    _train_csv(dead.run_dir, [math.nan] * 4 + [0.2] * 2 + [1.0] * 14)
    _train_csv(early.run_dir, [math.nan] * 4 + [0.2] * 14 + [1.0] * 2)  # at the bound for its last 2,000 frames
    record_launch(sdir, "hs", sweep, "local", {p.key: {"run_dir": str(p.run_dir), "overrides": []} for p in planned})
    got = {s.run_dir: s for s in collect({p.key: p.run_dir for p in planned}, root, sdir)}
    assert got[ok.run_dir].health == "" and not got[ok.run_dir].saturated
    assert got[dead.run_dir].health == "actor saturated since frame 6,000: its policy gradient is zero"
    assert got[dead.run_dir].saturated and not got[early.run_dir].saturated
    assert got[early.run_dir].health == ("actor at the bound since frame 18,000: 2,000 of the 10,000 frames that make "
                                         "it saturated")
    res = CliRunner().invoke(launch_app(), ["status", "hs", "--results-root", str(tmp_path)])
    code, out = res.exit_code, res.output
    assert code == 0 and "1 run(s) with a saturated actor" in out  # the shorter stretch is shown, not counted
    words = " ".join(out.split())
    assert "actor saturated since frame 6,000" in words and "actor at the bound since frame 18,000" in words
