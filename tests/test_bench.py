"""`repro bench` prints only ratios measured in the same run (no figure copied from a document)."""

from __future__ import annotations

import json
import re
import time

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from helpers import bench_app
from repro.bench.cli import same_run_ratios
from repro.bench.data import episode_lengths, synthetic_episode
from repro.bench.offline_update import available, run_offline_bench
from repro.bench.online_update import compose_learner
from repro.config.compose import offline_agents, online_agents


def _app() -> typer.Typer:
    return bench_app()


def test_same_run_ratios_pair_only_measured_settings():
    secs = {("taco", 4): 2.0, ("taco", 8): 3.0, ("drqv2", 4): 0.5, ("drqv2", 8): 1.5}
    assert same_run_ratios(secs) == {"taco_b8_over_taco_b4": 1.5, "drqv2_b8_over_drqv2_b4": 3.0,
                                     "taco_b4_over_drqv2_b4": 4.0, "taco_b8_over_drqv2_b8": 2.0}
    assert same_run_ratios({("taco", 1024): 6.0, ("drqv2", 256): 1.5}) == {"taco_b1024_over_drqv2_b256": 4.0}
    assert same_run_ratios({("taco", 256): 1.0}) == {}


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_bench_prints_same_run_ratios_and_no_constant(tmp_path):
    # one algorithm (the cheaper one) at two tiny batches keeps this fast; pairs across algorithms are
    # covered by the test above
    args = ["bench", "update", "--agent", "drqv2", "--batch", "2", "--batch", "4", "--repeats", "2", "--warmup", "0",
            "--fast", "--results", str(tmp_path)]
    result = CliRunner().invoke(_app(), args)
    assert result.exit_code == 0, result.output
    out = result.output
    assert "drqv2 B4 / drqv2 B2 update time" in out, out
    ratio_lines = [ln for ln in out.splitlines() if "x " in ln or ln.rstrip().endswith("x")]
    assert ratio_lines and all("measured in this run" in ln for ln in ratio_lines if " / " in ln)
    assert "upstream" not in out.lower() and "paper" not in out.lower()
    report = json.loads(next((tmp_path / "bench").glob("bench-*.json")).read_text())
    secs = {(r["agent"], r["batch_size"]): r["update_seconds"] for r in report["results"] if r["path"] == "plain"}
    assert report["ratios"] == same_run_ratios(secs)
    assert all(r["warmup"] == 0 and r["repeats"] == 2 and len(r["seconds_each"]) == 2 for r in report["results"])
    # --fast: timed beside the plain path of the same batch (alternated), as a ratio to it
    fast = {r["batch_size"]: r for r in report["results"] if r["path"] == "fast"}
    assert set(fast) == {2, 4} and all(r["alternated"] for r in report["results"])
    for b, row in fast.items():
        assert row["speedup_vs_plain"] == round(secs[("drqv2", b)] / row["update_seconds"], 3)
        assert f"drqv2 batch     {b} fast: " in out and "x the plain path (measured in this run" in out
    assert not any("upstream" in key for r in report["results"] for key in r)


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_every_online_agent_is_timed_on_a_batch_drawn_as_training_draws_it(tmp_path):
    """Every registered online agent, built-in or a plugin's (the offline ones: the --offline test below), is timed by
    `repro bench` at a tiny size, on a batch sampled from a ReplayBuffer with what its objectives ask for: a batch
    made by hand had no future_obs_seq and `repro bench update --agent spr` failed."""
    from repro.bench.online_update import replay_batch

    agents = online_agents()
    assert {"taco", "drqv2", "spr", "curl", "atc", "driml"} <= set(agents)
    args = ["bench", "update", *(x for a in agents for x in ("--agent", a)), "--batch", "2", "--repeats", "1",
            "--warmup", "0", "--results", str(tmp_path)]
    result = CliRunner().invoke(_app(), args)
    assert result.exit_code == 0, result.output
    report = json.loads(next((tmp_path / "bench").glob("bench-*.json")).read_text())
    assert [r["agent"] for r in report["results"]] == list(agents)
    assert all(r["update_seconds"] > 0 and r["frames_per_update"] == 4 for r in report["results"])
    agent, rc = compose_learner("spr", 2, "cheetah_run", "cpu", ["profile=tiny"])
    batch = replay_batch(agent, rc, 2, "cpu")
    assert agent.sample_options == {"future_seq": True} and batch["future_obs_seq"].shape[:2] == (2, rc.agent.K)


@pytest.mark.parametrize("args, needle", [(["--batch", "0"], "--batch must be >= 1"),
                                          (["--agent", "tacoo"], "unknown online agent 'tacoo'. Did you mean: taco"),
                                          (["--agent", "td3bc"], "unknown online agent 'td3bc'")])
def test_bench_bad_input_is_one_line(tmp_path, args, needle):
    result = CliRunner().invoke(_app(), ["bench", "update", *args, "--results", str(tmp_path)])
    assert result.exit_code == 2
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and needle in lines[0] and "Traceback" not in result.output


# ------------------------------------------------------------------------------------- offline learners

OFFLINE_LINE = re.compile(r"^(\w+) B(\d+)( \(its own batch size\))? / drqv2 B(\d+) update time: ([\d.]+)x "
                          r"\(measured in this run\)$")


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_offline_bench_prints_each_learners_ratio_to_drqv2_from_this_run(tmp_path):
    args = ["bench", "offline", "--batch", "2", "--repeats", "1", "--warmup", "0", "--dt-batch", "1",
            "--results", str(tmp_path)]
    result = CliRunner().invoke(_app(), args)
    assert result.exit_code == 0, result.output
    out = result.output.splitlines()
    report = json.loads(next((tmp_path / "bench").glob("bench-offline-*.json")).read_text())
    ref = report["results"][0]
    assert ref["agent"] == "drqv2" and ref["batch_size"] == 2 and ref["repeats"] == 1 and ref["warmup"] == 0
    timed = {r["agent"]: r for r in report["results"][1:]}
    expected = [a for a in offline_agents() if available(a) is None]
    assert list(timed) == expected and {"bc", "td3bc", "td3bc_taco", "cql", "cql_taco", "iql"} <= set(timed)
    lines = {m.group(1): m for m in map(OFFLINE_LINE.match, out) if m}
    assert set(lines) == set(expected)
    for agent, row in timed.items():
        m = lines[agent]
        assert int(m.group(2)) == row["batch_size"] == (1 if agent == "dt" else 2) and int(m.group(4)) == 2
        assert bool(m.group(3)) == (agent == "dt")
        ratio = row["update_seconds"] / ref["update_seconds"]  # recomputed from this run's two timings
        assert float(m.group(5)) == pytest.approx(ratio, abs=0.006)
        assert report["ratios"][f"{agent}_b{row['batch_size']}_over_drqv2_b2"] == round(ratio, 3)
    for agent in set(offline_agents()) - set(expected):
        assert f"{agent}: skipped (" in result.output
    assert "upstream" not in result.output.lower() and "paper" not in result.output.lower()


def test_an_unregistered_learner_is_skipped_with_its_reason(monkeypatch):
    from repro.bench.offline_update import LEARNERS

    monkeypatch.delitem(LEARNERS, "iql")
    assert "learner 'iql' is not registered" in available("iql") and "\n" not in available("iql")
    assert available("td3bc") is None
    assert "no agent file" in available("nonexistent_agent")
    said: list[str] = []
    report = run_offline_bench(2, 1, 0, "cpu", agents=["iql"], echo=said.append)
    assert report["skipped"] == {"iql": available("iql")} and len(report["results"]) == 1
    assert said[-1] == f"iql: skipped ({available('iql')})"


# ------------------------------------------------------------------------------------------ offline data

def test_offline_data_bench_loads_a_dataset_and_compares_sampling_with_the_online_buffer(tmp_path):
    args = ["bench", "data", "--transitions", "2000", "--episode-length", "250", "--batch", "32",
            "--sample-batches", "5", "--results", str(tmp_path)]
    result = CliRunner().invoke(_app(), args)
    assert result.exit_code == 0, result.output
    out = result.output
    report = json.loads(next((tmp_path / "bench").glob("bench-offline-data-*.json")).read_text())
    assert report["transitions"] == 2000 and report["episodes"] == 8
    assert report["raw_frame_bytes"] == (2000 + 8) * 3 * 84 * 84  # frames (T+1) of every episode, uint8
    assert report["replay_bytes"] == report["online_replay_bytes"]  # the same buffer layout, filled two ways
    ratios = report["ratios"]
    assert ratios["replay_bytes_over_raw_frames"] <= 1.10
    assert 0 < ratios["offline_over_online_batches_per_s"] and 0 < ratios["load_over_online_fill_time"]
    assert f"replay bytes / raw frame bytes: {ratios['replay_bytes_over_raw_frames']:.4f}" in out
    assert f"offline / online: {ratios['offline_over_online_batches_per_s']:.2f}x (measured in this run" in out
    assert "load_offline_data:" in out and "batches/s" in out


def test_synthetic_episodes_split_the_transitions_and_follow_the_dataset_contract():
    assert episode_lengths(2000, 500) == [500] * 4 and episode_lengths(1100, 500) == [500, 500, 100]
    ep = synthetic_episode(3, 7)
    assert ep["frames"].shape == (8, 3, 84, 84) and ep["frames"].dtype.name == "uint8"
    assert ep["actions"].shape == (7, 6) and ep["rewards"].shape == ep["discounts"].shape == (7,)
    assert not np.array_equal(ep["frames"][0], ep["frames"][1])  # the square moves


@pytest.mark.parametrize("args, needle", [(["offline", "--agent", "sac"], "unknown offline agent 'sac'"),
                                          (["data", "--transitions", "0"], "--transitions"),
                                          (["offline", "--dt-batch", "0"], "--dt-batch must be >= 1")])
def test_offline_bench_bad_input_is_one_line(tmp_path, args, needle):
    result = CliRunner().invoke(_app(), ["bench", *args, "--results", str(tmp_path)])
    assert result.exit_code == 2
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and needle in lines[0] and "Traceback" not in result.output


def test_offline_data_bench_times_the_offline_sampler_it_names(tmp_path, monkeypatch):
    """The loaded replay's sampler made slower by a known 40 ms a batch: the offline rate must show it (at most
    25 batches/s) and the online one must not, so a bench that timed one buffer twice, or swapped the two,
    fails here."""
    from repro.bench import data as bench_data

    real_load = bench_data.load_offline_data

    def slow_load(*args, **kwargs):
        data = real_load(*args, **kwargs)
        real_sample = data.buffer.sample

        def sample(*a, **k):
            time.sleep(0.04)
            return real_sample(*a, **k)

        data.buffer.sample = sample
        return data

    monkeypatch.setattr(bench_data, "load_offline_data", slow_load)
    report = bench_data.run_data_bench(transitions=500, batch_size=8, iters=5, episode_length=250, seed=0,
                                       work_dir=tmp_path, echo=lambda s: None)
    assert report["offline_batches_per_s"] <= 25.0 < report["online_batches_per_s"]
    assert report["ratios"]["offline_over_online_batches_per_s"] < 1.0


def _encoder_forward_flops(batch: int) -> int:
    """FLOPs of one DrQ-v2 encoder forward on (batch, 9, 84, 84): conv 9->32 stride 2 (41x41), three 32->32
    (39, 37, 35), counted from the shapes here and not by the code under test."""
    from repro.bench.roofline import conv_flops

    return (conv_flops(batch, 9, 32, 3, 41, 41)
            + sum(conv_flops(batch, 32, 32, 3, side, side) for side in (39, 37, 35)))


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_roofline_counts_the_updates_flops_and_names_the_kernels(tmp_path):
    """`repro bench roofline`: the DrQ-v2 update's forward convolutions are its two encoder passes (obs and
    next_obs) at the batch asked for, the peak convolution's FLOPs are its shape's, and each path's rate is its
    FLOPs over its measured seconds against the peak of its dtype, with the kernels that take its time."""
    import torch

    from repro.bench.roofline import TOP_KERNELS, conv_flops, flop_op, kernel_table

    args = ["bench", "roofline", "--agent", "drqv2", "--batch", "4", "--amp", "--repeats", "1", "--warmup", "0",
            "--results", str(tmp_path)]
    result = CliRunner().invoke(_app(), args)
    assert result.exit_code == 0, result.output
    assert "of this process's float32 convolution peak" in result.output, result.output
    report = json.loads(next((tmp_path / "bench").glob("bench-roofline-*.json")).read_text())
    (entry,) = report["roofline"]
    assert entry["flops_by_op"]["aten.convolution"] == 2 * _encoder_forward_flops(4)
    assert entry["flops"] == sum(entry["flops_by_op"].values()) and entry["flops_per_sample"] == entry["flops"] // 4
    n, c, h, w = entry["peaks"]["float32"]["shape"]
    assert entry["peaks"]["float32"]["flops"] == conv_flops(n, c, c, 3, h - 2, w - 2)
    assert set(entry["paths"]) == {"plain", "amp"}
    assert (entry["paths"]["plain"]["conv_dtype"], entry["paths"]["amp"]["conv_dtype"]) == ("float32", "bfloat16")
    for path in entry["paths"].values():
        rate = entry["flops"] / path["seconds"] / 1e9
        assert path["gflops_per_s"] == pytest.approx(rate, rel=0.01, abs=0.01)
        peak = entry["peaks"][path["conv_dtype"]]["gflops_per_s"]
        assert path["of_peak"] == pytest.approx(rate / peak, rel=0.01, abs=1e-4)
        kernels = path["kernels"]  # the top ones by self time (which they are depends on the machine's load)
        assert 0 < len(kernels) <= TOP_KERNELS and sum(k["share"] for k in kernels) <= 1.0 + 1e-3
        assert [k["self_seconds"] for k in kernels] == sorted((k["self_seconds"] for k in kernels), reverse=True)
    assert flop_op("aten::mkldnn_convolution") == "aten.convolution" and flop_op("aten::copy_") is None
    # every kernel (no top cut): the convolution kernels share out exactly the counter's convolution FLOPs
    conv = torch.nn.Conv2d(3, 8, 3)
    x = torch.randn(2, 3, 16, 16)
    rows = kernel_table(lambda: conv(x), {"aten.convolution": 1000}, top=10_000)
    assert sum(r["flops"] for r in rows if r["flop_op"] == "aten.convolution") == pytest.approx(1000, abs=len(rows))


# ------------------------------------------------------------------------------------------ subcommands
def test_each_mode_is_a_subcommand_and_the_old_forms_are_gone(tmp_path):
    """One form: `repro bench MODE --agent ...` (the one-command form `repro bench --e2e ...` and the other names of
    an agent file, --algo and --learner, are gone: issue 51)."""
    # each subcommand has its own options and help; bad input stays one line
    helps = CliRunner().invoke(_app(), ["bench", "--help"]).output
    assert all(sub in helps for sub in ("update", "e2e", "offline", "data", "roofline"))
    assert "--overlap" in CliRunner().invoke(_app(), ["bench", "e2e", "--help"]).output
    assert "--overlap" not in CliRunner().invoke(_app(), ["bench", "update", "--help"]).output
    for sub in ("update", "e2e", "offline", "roofline"):
        options = CliRunner().invoke(_app(), ["bench", sub, "--help"], terminal_width=200).output
        assert "--agent" in options and "--algo" not in options and "--learner" not in options, sub
    for args, needle in ((["update", "--batch", "0"], "--batch must be >= 1"),
                         (["e2e", "--task", "nope"], "unknown task 'nope'")):
        bad = CliRunner().invoke(_app(), ["bench", *args])
        assert bad.exit_code == 2 and len(bad.output.strip().splitlines()) == 1 and needle in bad.output, bad.output
    for old in (["--offline-data"], ["--e2e"], ["update", "--algo", "taco"], ["offline", "--learner", "cql"],
                ["update", "--iters", "2"]):
        gone = CliRunner().invoke(_app(), ["bench", *old, "--results", str(tmp_path / "old")])
        assert gone.exit_code == 2 and "No such option" in gone.output, (old, gone.output)
    assert not (tmp_path / "old").exists()


# ---------------------------------------------------------------------------------- merged files, load, progress
def _fake_time_update(seconds: dict[tuple[str, int, str], float]):
    """A stand-in for repro.bench.online_update.time_update: rows of the shape it writes, with ``seconds``' times
    (the real one times a B256 update in seconds; what is tested here is what the bench does with the rows)."""

    def time_update(agent, batch_size, repeats=2, device="cpu", paths=(), warmup=1, **_):
        return [{"agent": agent, "batch_size": batch_size, "path": p, "update_seconds": seconds[(agent, batch_size, p)],
                 "frames_per_update": 4, "fps_estimate": 4 / seconds[(agent, batch_size, p)], "repeats": repeats,
                 "warmup": warmup} for p in ("plain", *paths)]

    return time_update


def test_a_second_bench_merges_into_the_file_and_each_entry_records_the_load(tmp_path, monkeypatch):
    """`repro bench update` twice, with different agents: the second keeps the first's entries and replaces only those
    of the same (agent, batch, path) (a second bench used to replace the file, and the plan's headline moved with
    whichever ran last); every entry records the machine's 1-minute load average and cores beside it."""
    import os

    from repro.bench import cli as bench_cli
    from repro.bench import results as br

    times = {("taco", 8, "plain"): 2.0, ("taco", 8, "fast"): 0.5, ("drqv2", 8, "plain"): 1.0, ("drqv2", 8, "fast"): 0.4,
             ("alix", 8, "plain"): 3.0, ("alix", 16, "plain"): 4.0}
    monkeypatch.setattr(bench_cli, "time_update", _fake_time_update(times))
    first = CliRunner().invoke(_app(), ["bench", "update", "--agent", "taco", "--agent", "drqv2", "--batch", "8",
                                        "--fast", "--results", str(tmp_path)])
    assert first.exit_code == 0, first.output
    path = next((tmp_path / "bench").glob("bench-*-cpu.json"))
    assert {u.key for u in br.read(path).updates} == {("taco", 8, "plain"), ("taco", 8, "fast"),
                                                      ("drqv2", 8, "plain"), ("drqv2", 8, "fast")}
    times.update({("drqv2", 8, "plain"): 0.25, ("drqv2", 16, "plain"): 0.75})
    second = CliRunner().invoke(_app(), ["bench", "update", "--agent", "drqv2", "--agent", "alix", "--batch", "8",
                                         "--batch", "16", "--results", str(tmp_path)])
    assert second.exit_code == 0, second.output
    assert "4 entries timed now (1 replacing an entry of the same setting), 3 kept from earlier benches" in \
        second.output
    bench = br.read(path)
    seconds = {u.key: u.update_seconds for u in bench.updates}
    assert seconds[("taco", 8, "plain")] == 2.0 and seconds[("taco", 8, "fast")] == 0.5  # kept
    assert seconds[("drqv2", 8, "plain")] == 0.25 and seconds[("drqv2", 16, "plain")] == 0.75  # replaced, added
    assert seconds[("alix", 8, "plain")] == 3.0 and len(seconds) == 7
    assert [u.key for u in bench.updates][:4] == [("taco", 8, "plain"), ("taco", 8, "fast"), ("drqv2", 8, "plain"),
                                                  ("drqv2", 8, "fast")]  # replaced in place
    raw = json.loads(path.read_text())
    assert raw["format"] == br.FORMAT and all("path" in r and "speedup" not in r for r in raw["results"])
    for entry in bench.updates:  # the load beside each entry: a load average, on this machine's cores
        assert entry.load is not None and entry.load >= 0 and entry.cores == os.cpu_count()
    assert f"on {os.cpu_count()} cores" in second.output


def test_a_bench_shows_each_setting_as_it_is_timed(tmp_path, monkeypatch):
    """On a terminal `repro bench update` shows a progress bar naming the setting being timed; in a log each
    setting's line comes as it is done, after a first line naming all of them (it printed nothing for minutes)."""
    import io

    from rich.console import Console

    from repro.bench import cli as bench_cli
    from repro.bench import progress

    screen = io.StringIO()
    monkeypatch.setattr(progress, "_bar_console", lambda: Console(file=screen, force_terminal=True, width=120))
    times = {("taco", 8, "plain"): 0.5, ("drqv2", 8, "plain"): 0.25}
    order: list[str] = []
    fake = _fake_time_update(times)

    def time_update(agent, batch_size, **kw):
        order.append(f"timed {agent}")
        return fake(agent, batch_size, **kw)

    monkeypatch.setattr(bench_cli, "time_update", time_update)
    bench_cli.run_bench([("taco", 8), ("drqv2", 8)], 1, "cpu", tmp_path, echo=order.append, progress=True)
    assert "timing taco B8 (plain)" in screen.getvalue() and "2/2" in screen.getvalue()
    assert order[0].startswith("timing 2 setting(s): taco B8, drqv2 B8; paths plain")
    assert order[1] == "timed taco" and order[2].startswith("  taco batch     8: ") and order[3] == "timed drqv2"
    screen.truncate(0)
    bench_cli.run_bench([("taco", 8)], 1, "cpu", tmp_path, echo=lambda s: None, progress=False)
    assert screen.getvalue() == ""  # not a terminal: no bar


def test_a_file_of_format_2_reads_and_is_written_with_the_fields_own_key(tmp_path):
    """Format 2 wrote the field ``path`` as "speedup": such a file still reads, and a bench that merges into it writes
    every entry, old and new, with the key "path"."""
    from repro.bench import results as br

    path = tmp_path / "bench" / br.file_name(br.ONLINE, "cpu")
    path.parent.mkdir()
    path.write_text(json.dumps({"kind": "online", "format": 2, "device": "cpu", "results": [
        {"agent": "taco", "batch_size": 8, "speedup": "fast", "update_seconds": 0.5, "frames_per_update": 4}]}))
    assert [u.key for u in br.read(path).updates] == [("taco", 8, "fast")]
    bench = br.read_or_new(path, br.ONLINE, "cpu")
    bench.merge(updates=[br.UpdateEntry("drqv2", 8, "plain", 1.0)])
    written = bench.to_json()
    assert [(r["agent"], r["path"]) for r in written["results"]] == [("taco", "fast"), ("drqv2", "plain")]
    assert written["format"] == br.FORMAT == 3 and not any("speedup" in r for r in written["results"])
