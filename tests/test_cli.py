"""The `repro` CLI as a user types it: tasks, dry runs, bad input, a Meta-world run with success."""

import ast
import functools
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from helpers import write_sweep
from repro.envs import TASKS
from repro_app.cli import app

runner = CliRunner()
ROOT = Path(__file__).resolve().parents[1]


@functools.cache
def _package_trees() -> list[tuple[Path, ast.Module]]:
    """Every module of the packages, parsed once: (path relative to the checkout, tree)."""
    return [(path.relative_to(ROOT), ast.parse(path.read_text(encoding="utf-8")))
            for pkg in ("repro", "repro_app", "analysis", "paper_figures", "repro_data")
            for path in sorted((ROOT / pkg).rglob("*.py"))]


def repro(*args: str, timeout: int = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "repro", *args], capture_output=True, text=True, timeout=timeout)


def test_the_command_line_starts_without_torch():
    """`repro --help`, `status`, `sweep` (the launcher itself) and bad input need no torch: the commands that train or
    time import it when they run (about 2 s of every start otherwise). Fails when a CLI module imports torch (or a
    module that does) at the top. Nor wandb (about 1 s): only runtime.wandb=true loads it."""
    code = ("import sys, repro_app.cli; "
            "print(sorted(m for m in ('torch', 'dm_control', 'matplotlib', 'wandb') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "[]", out.stdout + out.stderr


def test_a_run_without_runtime_wandb_does_not_import_wandb(tmp_path):
    """The trainer, both loops and their loggers (TensorBoard on) write rows without loading wandb; with
    runtime.wandb=true the same logger does (so this test can fail)."""
    code = ("import sys, pathlib; from repro.train import api, online_loop, offline_loop; "
            "from repro.runs.logger import RunLogger; pathlib.Path(sys.argv[1]).mkdir(); "
            "from repro.runs.wblog import WandbRun; wb = WandbRun('offline', 'p', None, 'g', 'g/n', ('seed=1',)); "
            "log = RunLogger(sys.argv[1], [], echo=lambda s: None, tensorboard=True, "
            "wandb=wb if sys.argv[2] == 'on' else None); log.log_train({'frame': 100}); log.close(); "
            "print('wandb' in sys.modules)")
    for switch, loaded in (("off", "False"), ("on", "True")):
        out = subprocess.run([sys.executable, "-c", code, str(tmp_path / switch), switch], capture_output=True,
                             text=True, timeout=120)
        assert out.returncode == 0 and out.stdout.strip() == loaded, out.stdout + out.stderr


def test_tasks_lists_every_task_with_action_dim_and_defaults():
    result = runner.invoke(app, ["tasks"], terminal_width=200)
    assert result.exit_code == 0, result.output
    for name, info in TASKS.items():
        line = next(ln for ln in result.output.splitlines() if f" {name} " in ln)
        assert f" {info.action_dim} " in line
    qr = next(ln for ln in result.output.splitlines() if " quadruped_run " in ln)
    hh = next(ln for ln in result.output.splitlines() if " hopper_hop " in ln)
    assert " 1 " in qr.split("medium")[1][:6]  # K=1 on quadruped_run
    assert " 3 " in hh.split("medium")[1][:6]  # K=3 on hopper_hop


@pytest.mark.parametrize("args,needle", [
    (["task=hoper_hop"], "hopper_hop"),
    (["agent=tacoo"], "taco"),
    (["agent.KK=3"], "K"),
    (["agent.K=abc"], "agent.K"),
    (["agent.reward_target=sum"], "nstep"),
    (["agent.objectives.spr2=1"], "objective"),
    (["seed"], "key=value"),
])
def test_bad_input_is_one_line_and_exit_2(args, needle):
    out = repro("train", "--dry-run", *args, timeout=120)
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1, out.stderr
    assert needle in lines[0] and "Traceback" not in out.stderr


def test_dry_run_prints_config_and_parameter_table_without_training(tmp_path):
    result = runner.invoke(app, ["train", "--dry-run", "agent=drqv2", "task=walker_run",
                                 f"runtime.results_root={tmp_path}"], terminal_width=200)
    assert result.exit_code == 0, result.output
    assert "batch_size: 512" in result.output and "nstep: 1" in result.output
    assert "encoder" in result.output and "total" in result.output
    assert "objective" not in result.output.split("trainable parameters")[1]
    assert not any(tmp_path.iterdir())  # nothing written
    result = runner.invoke(app, ["train", "--dry-run", "task=cheetah_run", "env.distracting_dims=20"],
                           terminal_width=200)
    assert "|A|=26" in result.output and "objective.taco" in result.output


@pytest.mark.slow
def test_metaworld_tiny_run_logs_success(tmp_path):
    out = repro("train", "profile=tiny", "task=hand-insert", "train.frames=80", "train.seed_frames=40",
                "train.eval_every_frames=80", "env.max_episode_frames=40", "runtime.threads=1",
                f"runtime.results_root={tmp_path}", timeout=600)
    assert out.returncode == 0, out.stderr
    run = tmp_path / "default/taco/base/hand-insert/seed_1"
    ev = pd.read_csv(run / "eval.csv")
    assert list(ev["frame"]) == [0, 80]
    assert ev["success"].between(0, 1).all() and ev["success"].notna().all()
    tr = pd.read_csv(run / "train.csv")
    assert tr["success"].notna().all()


def test_sweep_results_flag_is_the_results_root(tmp_path, monkeypatch):
    """`repro sweep --results ROOT` (like `repro status`): the plan and the runs live under ROOT."""
    monkeypatch.chdir(tmp_path)
    result = runner.invoke(app, ["sweep", "tiny", "--dry-run", "--results", "my runs"], terminal_width=240)
    assert result.exit_code == 0, result.output
    assert f"Results root: {tmp_path / 'my runs'}" in result.output.replace("\n", "")
    assert "absent" in result.output and not (tmp_path / "my runs").exists()

    both = runner.invoke(app, ["sweep", "tiny", "--dry-run", "-r", "a", "--set", "runtime.results_root=b"])
    assert both.exit_code == 2 and "not both" in both.output


def test_sweep_short_results_flag_launches_under_root(tmp_path):
    """`-r ROOT` is `--results ROOT` for sweep and status (a dry run: the launch itself is the one every
    launcher test makes)."""
    sweep = write_sweep(tmp_path, "res", ["reacher_hard"], {"base": []}, 1)
    root = tmp_path / "elsewhere"
    result = runner.invoke(app, ["sweep", str(sweep), "-r", str(root), "--dry-run"], terminal_width=400)
    assert result.exit_code == 0, result.output
    assert "res/taco/base/reacher_hard/seed_1" in result.output and f"Results root: {root}\n" in result.output
    missing = runner.invoke(app, ["status", "-r", str(root)], terminal_width=240)  # a dry run creates no root
    assert missing.exit_code == 2 and "does not exist" in missing.output, missing.output
    root.mkdir()
    status = runner.invoke(app, ["status", "-r", str(root)], terminal_width=240)
    assert status.exit_code == 0 and f"no sweep launched under {root}" in status.output, status.output
    assert not (tmp_path / "runs").exists()


def test_every_command_fails_and_prints_through_the_one_console_helper():
    """repro/runs/console.py is the only place that defines a command's error exit (``fail``) or builds a rich
    Console: a copy defined elsewhere (a module's own ``_fail``, its own Console width) fails here by file:line."""
    found = []
    for path, tree in _package_trees():
        if path.parts[0] != "repro_data" and path != Path("repro/runs/console.py"):
            for node in ast.walk(tree):
                called = getattr(node.func, "id", getattr(node.func, "attr", "")) if isinstance(node, ast.Call) else ""
                named = node.name.lstrip("_") if isinstance(node, ast.FunctionDef) else ""
                if called == "Console" or named in ("fail", "die", "console"):
                    found.append(f"{path}:{node.lineno}")
    assert not found, found
    from repro.runs.console import fail

    result = CliRunner().invoke(app, ["train", "agent=no_such_agent"])
    assert result.exit_code == 2 and result.output.count("error:") == 1 and "\x1b" not in result.output
    with pytest.raises(Exception) as exc:  # typer.Exit carries the code
        fail("x", 7)
    assert getattr(exc.value, "exit_code", None) == 7


# Issue 37: an objective's parameters are typed by the dataclass registered with it (ObjectiveSpec.params) and checked
# before anything is written, by `repro train` and `repro sweep`, with and without --dry-run.
OBJECTIVE_EDGES = [
    (["agent=spr", "agent.objective_params.spr.momentum=abc"],
     "agent.objective_params.spr.momentum must be a number (got 'abc')."),
    (["agent=spr", "agent.objective_params.spr.projection_dim=4.5"],  # was truncated to 4
     "agent.objective_params.spr.projection_dim must be an integer or null (got 4.5)."),
    (["agent=atc", "agent.objective_params.atc.predictor_hidden=8.0"],
     "agent.objective_params.atc.predictor_hidden must be an integer (got 8.0)."),
    (["agent=spr", "agent.objective_params.spr.rollout=abc"],  # was read as true
     "agent.objective_params.spr.rollout must be true or false (got 'abc')."),
    (["agent=spr", "agent.objective_params.spr.rollout=2"],  # OmegaConf reads a number as a flag: 2 was true
     "agent.objective_params.spr.rollout must be true or false (got 2)."),
    (["agent=spr", "agent.objective_params.spr.rollout=0"],  # and 0 false
     "agent.objective_params.spr.rollout must be true or false (got 0)."),
    (["agent=spr", "+agent.objective_params.spr.projectoin_dim=4"],  # was a traceback from the objective's __init__
     "unknown setting agent.objective_params.spr.projectoin_dim of objective 'spr'. Did you mean: projection_dim?"),
    (["agent=taco", "+agent.objective_params.spr.projectoin_dim=4"],  # checked though spr is not trained
     "unknown setting agent.objective_params.spr.projectoin_dim of objective 'spr'. Did you mean: projection_dim?"),
    (["agent=driml", "+agent.objective_params.driml.hidden=4"],  # was a traceback
     "agent.objective_params.driml: objective 'driml' takes no parameters (got hidden)."),
    (["agent=spr", "agent.objective_params.spr.momentum=1.0"],  # was a traceback from MomentumTarget
     "agent.objective_params.spr.momentum must be in [0.0, 1.0) (got 1.0)."),
    (["agent=taco", "agent.objectives.foo=1.0"],  # listed taco, curl, reward (the agent file's) as known
     "unknown objective 'foo' in agent.objectives. Registered objectives: taco, curl, reward, spr, atc, driml"),
    (["agent=taco", "+agent.objective_params.nope.x=1"],
     "unknown objective 'nope' in agent.objective_params. Registered objectives: taco, curl, reward, spr, atc, driml"),
    (["agent=taco", "agent.objectives.spr=1.0"],
     "agent.objectives.spr is not in the agent file's config: add it with +agent.objectives.spr=1.0."),
]


@pytest.mark.parametrize("overrides,message", OBJECTIVE_EDGES)
def test_a_bad_objective_parameter_is_one_line_and_exit_2_before_anything_is_written(tmp_path, overrides, message):
    for dry_run in (["--dry-run"], []):
        result = runner.invoke(app, ["train", *dry_run, "task=cheetah_run", "profile=tiny", *overrides,
                                     f"runtime.results_root={tmp_path}"], terminal_width=400)
        lines = result.output.strip().splitlines()
        assert result.exit_code == 2 and len(lines) == 1 and lines[0].startswith(f"error: {message}"), result.output
        sets = [x for o in overrides[1:] for x in ("--set", o)]
        result = runner.invoke(app, ["sweep", "tiny", *dry_run, "--tasks", "cheetah_run", "--seeds", "1", *sets,
                                     "--set", overrides[0], "-r", str(tmp_path)], terminal_width=400)
        assert result.exit_code == 2 and message in result.output, result.output
        assert len(result.output.strip().splitlines()) == 1, result.output
    assert not any(tmp_path.iterdir())  # nothing written


def test_objective_parameters_are_read_typed():
    from repro.agent.objectives.base import ObjectiveContext
    from repro.agent.objectives.common import typed_params
    from repro.config.compose import compose, objective_params, typed
    from repro.config.schema import SPRParams

    params = objective_params("spr", {"momentum": 0, "projection_dim": "8"})
    assert params == SPRParams(momentum=0.0, projection_dim=8, rollout=True)
    assert isinstance(params.momentum, float) and objective_params("taco", None) is None
    agent = typed(compose(["agent=spr", "profile=tiny", "agent.objective_params.spr.projection_dim=8"])).agent
    assert agent.objective_params["spr"]["projection_dim"] == 8  # the config is left as given (its run's identity)
    ctx = ObjectiveContext(repr_dim=4, feature_dim=4, hidden_dim=4, action_dim=1, K=1, seq_dim=1)
    assert typed_params(ctx, SPRParams) == SPRParams()  # a context built by hand: the registered defaults


# Issue 51.5: one UserError base, caught once by the app (repro/runs/console.py Commands).
# The base itself, and the exceptions of control flow (never shown to a user as an error).
INTERNAL_EXCEPTIONS = {"UserError", "NotEnoughData", "Interrupted", "_AlreadyComplete", "RunInterrupted"}


def test_every_user_facing_error_derives_from_user_error_and_no_command_lists_them():
    """Every exception class of the packages that derives from a built-in exception also derives from UserError
    (except the control-flow ones above), so a new error type is one line, exit 2, with no command to update; and
    no command catches a UserError only to print it (an ``except`` whose body is ``fail(str(exc))``)."""
    builtin = {"Exception", "ValueError", "KeyError", "RuntimeError", "OSError", "FileNotFoundError", "TypeError",
               "LookupError"}
    missing, lists = [], []
    for path, tree in _package_trees():
        for node in ast.walk(tree):
            where = f"{path}:{getattr(node, 'lineno', '')}"
            if isinstance(node, ast.ClassDef):
                bases = {getattr(b, "id", getattr(b, "attr", "")) for b in node.bases}
                if bases & builtin and "UserError" not in bases and node.name not in INTERNAL_EXCEPTIONS:
                    missing.append(f"{where} {node.name}")
            if isinstance(node, ast.ExceptHandler) and node.name and len(node.body) == 1 \
                    and path != Path("repro/runs/console.py"):  # the one catch
                if ast.unparse(node.body[0]) == f"fail(str({node.name}))":
                    lists.append(f"{where} {ast.unparse(node.type) if node.type else ''}")
    assert not missing, missing
    assert not lists, lists


def test_a_user_error_of_any_command_is_one_line_exit_2():
    """The app's group catches UserError: a command of an app built as `repro` builds it raises a new subclass and
    gets one line, exit 2, no traceback; the `repro` app itself is built on that group."""
    import typer
    from typer.main import get_command

    from repro.config.errors import UserError
    from repro.runs.console import Commands

    class NewError(UserError, ValueError):
        pass

    sub = typer.Typer(cls=Commands)

    @sub.command()
    def one() -> None:
        raise NewError("a new kind of bad input")

    @sub.command()
    def two() -> None:
        pass

    result = runner.invoke(sub, ["one"])
    assert result.exit_code == 2 and result.output == "error: a new kind of bad input\n", result.output
    assert isinstance(get_command(app), Commands)


# Issue 50.4: guard rails. Every output path a command writes, as a regular file or under one (unwritable even for
# root): one line, exit 2, nothing written.
def _outputs(file, sweep):
    sub = file / "sub"
    return [
        (["report", "--out", str(sub), "--results", str(file.parent / "none")], f"--out {sub} cannot be made"),
        (["figures", "F1", "--out", str(file)], f"--out {file} is a file"),
        (["audit", "--out", str(sub)], f"--out {sub} cannot be made"),
        (["plan", "main", "--out", str(file)], f"--out {file} is a file"),
        (["verify", "--judge-only", "--out", str(sub), "-r", str(file.parent)], f"--out {sub} cannot be made"),
        (["plot", str(file.parent), "--out", str(sub / "p.png")], f"its folder {sub} cannot be made"),
        (["sweep", str(sweep), "-r", str(file)], f"results root {file} is a file"),
        (["sweep", str(sweep), "-r", str(sub)], f"results root {sub} cannot be made"),
        (["train", "profile=tiny", f"runtime.results_root={sub}"], f"runtime.results_root {sub} cannot be made"),
        (["dataset", "export", str(file.parent), "--format", "drqv2", "--out", str(sub)], f"--out {sub} cannot be"),
        (["reproduce", "--results", str(sub)], f"--results {sub} cannot be made"),
        (["bench", "data", "--results", str(file)], f"--results {file} is a file"),
    ]


def test_an_output_path_that_is_a_file_or_under_one_is_one_line_exit_2_before_anything_is_written(tmp_path):
    sweep = write_sweep(tmp_path, "guard", ["reacher_hard"], {"base": []}, 1)
    file = tmp_path / "a_file"
    file.write_text("kept\n")
    before = sorted(p.name for p in tmp_path.iterdir())
    for args, needle in _outputs(file, sweep):
        result = runner.invoke(app, args, terminal_width=400)
        lines = result.output.strip().splitlines()
        assert result.exit_code == 2 and len(lines) == 1 and lines[0].startswith("error: "), (args, result.output)
        assert needle in lines[0] and isinstance(result.exception, SystemExit), (args, result.output)
    assert sorted(p.name for p in tmp_path.iterdir()) == before and file.read_text() == "kept\n"

