"""`repro bench e2e` (repro/bench/e2e.py): a tiny real training loop's JSON has every phase, the phases add up to
the loop's wall clock, FPS is frames over that wall clock, and `repro plan` reads the entries by path."""

from __future__ import annotations

import json

import pytest
import typer
from typer.testing import CliRunner

from helpers import bench_app
from repro.bench import results as bench_results
from repro.bench.e2e import PHASES

# The phases are timed one by one and the wall clock around the whole loop: what they leave out is the loop's own
# bookkeeping (a few microseconds a step), so their sum is within this fraction of the wall clock.
SUM_TOLERANCE = 0.10


def _app() -> typer.Typer:
    return bench_app()


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_e2e_json_has_every_phase_summing_to_the_wall_clock(tmp_path):
    bench_dir = tmp_path / "bench"
    args = ["bench", "e2e", "--agent", "drqv2", "--amp", "--frames", "100", "--seed-frames", "20",
            "--results", str(tmp_path)]
    result = CliRunner().invoke(_app(), args)
    assert result.exit_code == 0, result.output
    path = next(p for p in bench_dir.glob("bench-*-cpu.json"))
    report = json.loads(path.read_text())
    entries = report["e2e"]
    assert report["kind"] == "online" and report["format"] == bench_results.FORMAT
    assert [(e["agent"], e["path"], e["profile"], e["batch_size"]) for e in entries] == [
        ("drqv2", "plain", "tiny", 8), ("drqv2", "amp", "tiny", 8)]
    for e in entries:
        assert set(e["phases"]) == set(PHASES)
        # 100 frames = 50 agent steps past the seed frames, crossing the first 50-step episode's end
        assert e["frames"] == 100 and e["updates"] == 25 and e["device"] == "cpu" and e["cpu"]
        assert all(e["phases"][k] > 0 for k in PHASES), e["phases"]
        total = sum(e["phases"].values())
        assert (1 - SUM_TOLERANCE) * e["seconds"] <= total <= e["seconds"] + 1e-3, (total, e["seconds"])
        assert e["fps"] == pytest.approx(e["frames"] / e["seconds"], rel=1e-3)
    assert all(e["phase_sync"] for e in entries)
    # a second run, timed as it trains (--overlap: phases not synchronized), keeps the entries timed phase by phase
    # and `results` (here an update entry as an earlier version wrote it); it replaces only an entry of the same agent,
    # batch, profile, path and timing
    report["results"] = [{"algo": "drqv2", "batch_size": 8, "speedup": "plain", "update_seconds": 0.5}]
    stale = {**entries[0], "phase_sync": False, "seconds": 99.0}  # an earlier --overlap entry: replaced
    path.write_text(json.dumps({**report, "e2e": [*entries, stale]}))
    short = ["bench", "e2e", "--agent", "drqv2", "--frames", "20", "--seed-frames", "20", "--results", str(tmp_path)]
    result = CliRunner().invoke(_app(), [*short, "--overlap"])  # without --amp, and shorter
    assert result.exit_code == 0, result.output
    again = json.loads(path.read_text())
    assert [(e["path"], e["phase_sync"]) for e in again["e2e"]] == [("plain", True), ("amp", True),
                                                                      ("plain", False)]
    bench = bench_results.read(path)
    (update,) = bench.updates
    assert (update.agent, update.batch_size, update.path, update.update_seconds) == ("drqv2", 8, "plain", 0.5)
    assert again["e2e"][:2] == entries and again["e2e"][2]["seconds"] != 99.0
    assert all("load" in e and "cores" in e for e in again["e2e"])  # the machine's load beside each entry
    assert "as it trains" in result.output and set(again["e2e"][2]["phases"]) == set(PHASES)
    # the one FPS (`repro plan`, T4/T5) takes the loop as it trains where there is one
    assert bench_results.rate(bench, "drqv2", 8, "plain").fps == pytest.approx(again["e2e"][2]["fps"], rel=1e-3)
    assert bench_results.rate(bench, "drqv2", 8, "amp").fps == pytest.approx(entries[1]["fps"], rel=1e-3)


@pytest.mark.parametrize("args, needle", [(["--frames", "0"], "--frames must be >= 1"),
                                          (["--task", "nope"], "unknown task 'nope'"),
                                          (["--agent", "td3bc"], "unknown online agent 'td3bc'")])
def test_e2e_bad_input_is_one_line_exit_2(tmp_path, args, needle):
    result = CliRunner().invoke(_app(), ["bench", "e2e", *args, "--results", str(tmp_path)])
    assert result.exit_code == 2 and needle in result.output, result.output
    assert len(result.output.strip().splitlines()) == 1
