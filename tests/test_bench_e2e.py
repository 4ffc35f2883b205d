"""`repro bench --e2e` (repro/bench/e2e.py): a tiny real training loop's JSON has every phase, the phases add up to
the loop's wall clock, FPS is frames over that wall clock, and `repro plan` reads the entries by path."""

from __future__ import annotations

import json

import pytest
import typer
from typer.testing import CliRunner

from helpers import bench_app
from repro.bench.e2e import PHASES
from repro_app.plan import parse_bench

# The phases are timed one by one and the wall clock around the whole loop: what they leave out is the loop's own
# bookkeeping (a few microseconds a step), so their sum is within this fraction of the wall clock.
SUM_TOLERANCE = 0.10


def _app() -> typer.Typer:
    return bench_app()


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_e2e_json_has_every_phase_summing_to_the_wall_clock(tmp_path):
    bench_dir = tmp_path / "bench"
    args = ["bench", "--e2e", "--algo", "drqv2", "--amp", "--frames", "100", "--seed-frames", "20",
            "--results", str(tmp_path)]
    result = CliRunner().invoke(_app(), args)
    assert result.exit_code == 0, result.output
    path = next(p for p in bench_dir.glob("bench-*-cpu.json"))
    report = json.loads(path.read_text())
    entries = report["e2e"]
    assert [(e["algo"], e["speedup"], e["profile"], e["batch_size"]) for e in entries] == [
        ("drqv2", "plain", "tiny", 8), ("drqv2", "amp", "tiny", 8)]
    for e in entries:
        assert set(e["phases"]) == set(PHASES)
        # 100 frames = 50 agent steps past the seed frames, crossing the first 50-step episode's end
        assert e["frames"] == 100 and e["updates"] == 25 and e["device"] == "cpu" and e["cpu"]
        assert all(e["phases"][k] > 0 for k in PHASES), e["phases"]
        total = sum(e["phases"].values())
        assert (1 - SUM_TOLERANCE) * e["seconds"] <= total <= e["seconds"] + 1e-3, (total, e["seconds"])
        assert e["fps"] == pytest.approx(e["frames"] / e["seconds"], rel=1e-3)
    # a second run replaces the entry of the same algo, batch, profile and path, keeps the others and `results`
    report["results"] = [{"algo": "drqv2", "batch_size": 8, "speedup": "plain", "update_seconds": 0.5}]
    path.write_text(json.dumps(report))
    result = CliRunner().invoke(_app(), args[:4] + args[5:])  # without --amp
    assert result.exit_code == 0, result.output
    again = json.loads(path.read_text())
    assert [e["speedup"] for e in again["e2e"]] == ["amp", "plain"] and again["results"] == report["results"]
    bench = parse_bench(again, path, "cpu")
    plain, amp = bench.e2e[("drqv2", 8, "plain")], bench.e2e[("drqv2", 8, "amp")]
    assert plain == again["e2e"][1] and amp == entries[1]


@pytest.mark.parametrize("args, needle", [(["--frames", "0"], "--frames must be >= 1"),
                                          (["--task", "nope"], "unknown task 'nope'"),
                                          (["--offline"], "drop --offline")])
def test_e2e_bad_input_is_one_line_exit_2(tmp_path, args, needle):
    result = CliRunner().invoke(_app(), ["bench", "--e2e", *args, "--results", str(tmp_path)])
    assert result.exit_code == 2 and needle in result.output, result.output
    assert len(result.output.strip().splitlines()) == 1
