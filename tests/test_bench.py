"""`repro bench` prints only ratios measured in the same run (no figure copied from a document)."""

from __future__ import annotations

import json

import pytest
import typer
from typer.testing import CliRunner

from repro.bench import register, same_run_ratios


def _app() -> typer.Typer:
    app = typer.Typer()
    register(app)

    @app.callback()
    def main() -> None:  # keep `bench` a named sub-command
        pass

    return app


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
    args = ["bench", "--algo", "drqv2", "--batch", "2", "--batch", "4", "--repeats", "1", "--warmup", "0",
            "--results", str(tmp_path)]
    result = CliRunner().invoke(_app(), args)
    assert result.exit_code == 0, result.output
    out = result.output
    assert "drqv2 B4 / drqv2 B2 update time" in out, out
    ratio_lines = [ln for ln in out.splitlines() if "x " in ln or ln.rstrip().endswith("x")]
    assert ratio_lines and all("measured in this run" in ln for ln in ratio_lines if " / " in ln)
    assert "upstream" not in out.lower() and "paper" not in out.lower()
    report = json.loads(next((tmp_path / "bench").glob("bench-*.json")).read_text())
    secs = {(r["algo"], r["batch_size"]): r["update_seconds"] for r in report["results"]}
    assert report["ratios"] == same_run_ratios(secs)
    assert all(r["warmup"] == 0 and r["repeats"] == 1 for r in report["results"])
    assert not any("upstream" in key for r in report["results"] for key in r)


@pytest.mark.parametrize("args, needle", [(["--batch", "0"], "--batch must be >= 1"),
                                          (["--algo", "sac"], "unknown algo 'sac'")])
def test_bench_bad_input_is_one_line(tmp_path, args, needle):
    result = CliRunner().invoke(_app(), ["bench", *args, "--results", str(tmp_path)])
    assert result.exit_code == 2
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and needle in lines[0] and "Traceback" not in result.output
