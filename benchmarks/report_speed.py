"""The analysis commands at the paper's scale: writes the full-coverage tree of tests/analysis_fixtures.py with the
paper's budgets (6 seeds, 1M frames, an evaluation every 10K frames, a train.csv row per 1000-frame episode, the
final evaluation's frames as a trained run saves them; offline runs of 100K updates evaluated every 10K) and times
``repro report`` (with an empty cache, then again on the unchanged tree: the incremental report), ``repro figures
--all``, ``repro claims`` and ``repro plan --claims`` on it, each in its own process, with its CPU seconds and peak
memory (the largest resident set of the process and the children it waited for). An existing output folder is
emptied first, except for the commands that reuse the report's (``report-again``: the unchanged tree;
``report-batch``: a batch of six runs changed; ``plan-after-report`` and ``plan-again``: ``repro plan --claims``
into the report's folder, as its default --out is).

    python benchmarks/report_speed.py --root /tmp/paper-scale            # writes the tree once, then times all
    python benchmarks/report_speed.py --root /tmp/paper-scale --only report --json /tmp/t.json

Not a test: the numbers go to docs/performance.md ("The report at the paper's scale"). Run it on a quiet
machine (``uptime``), or say what the load was. Each command runs with the Python that runs this script and the
inherited environment (PYTHONPATH picks the code timed); ``OMP_NUM_THREADS=1`` is set for one core. Python runs them
as it does by default, with compiled modules cached (``PYTHONDONTWRITEBYTECODE`` is removed, and the project's
packages are compiled once before the first command, as installing them does): a machine that sets it compiles
about 120 modules of this project at every command (0.2 s here).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

from repro.runs.rundir import cpu_model

REPO = Path(__file__).resolve().parents[1]
# save_frames: every done online run keeps its final evaluation's frames (frames.npz), as train.save_frames (on by
# default) makes a trained run do; F13 reads them instead of rendering random-action frames
# save_tsne: the t-SNE run (distracting action dims) keeps F6's embedding of its final encoder (tsne.npz), as a trained
# run with distracting dims writes it at its final evaluation (repro/train/action_tsne.py); F6 reads it
PAPER_SCALE = {"frames": 1_000_000, "eval_every": 10_000, "train_rows": 1000, "save_frames": True,
               "save_tsne": True, "updates": 100_000, "eval_every_updates": 10_000}
# name: (arguments, output folder). ``report-again`` reruns the report into the same folder: the incremental report
# on an unchanged tree (analysis/cache.py); ``report-batch`` the same after a batch of runs changed (BATCH: the last
# evaluation of one cell's six seeds one point higher; restored afterwards); ``plan-after-report`` and
# ``plan-again`` run ``repro plan --claims`` into the report's folder (its default --out is the report's) once and
# again. The others start without a cache (their own folders, emptied first).
COMMANDS = {
    "report": (["report"], "report"),
    "report-again": (["report"], "report"),
    "report-batch": (["report"], "report"),
    "plan-after-report": (["plan", "--claims"], "report"),
    "plan-again": (["plan", "--claims"], "report"),
    "figures": (["figures", "--all"], "figures"),
    "claims": (["claims"], "claims"),
    "plan": (["plan", "--claims"], "plan"),
}
KEEPS_CACHE = ("report-again", "report-batch", "plan-after-report", "plan-again")
PACKAGES = ("repro", "repro_data", "analysis", "paper_figures", "repro_app")  # compiled before the first command
BATCH = "main/taco/base/quadruped_run"  # the cell whose seeds' eval.csv the batch changes


def write_tree(root: Path, seeds: int) -> int:
    """The paper-scale tree under ``root`` (skipped when its marker says it is complete); returns its runs."""
    marker = root / ".paper_scale.json"
    if marker.exists():
        written = json.loads(marker.read_text())
        if written.get("seeds") == seeds and all(written.get(k) == v for k, v in PAPER_SCALE.items()):
            return int(written["runs"])
    if root.exists():
        shutil.rmtree(root)
    sys.path.insert(0, str(REPO))
    from tests.analysis_fixtures import full_coverage_root

    full_coverage_root(root, seeds=seeds, **PAPER_SCALE)
    runs = sum(1 for _ in root.rglob("config.yaml"))
    marker.write_text(json.dumps({"runs": runs, "seeds": seeds, **PAPER_SCALE}))
    return runs


@contextlib.contextmanager
def changed_batch(root: Path) -> Iterator[None]:
    """A batch of runs lands: the last evaluation of :data:`BATCH`'s seeds one point higher while the block runs,
    then the files as they were (their bytes and modification times)."""
    files = sorted((root / BATCH).glob("seed_*/eval.csv"))
    if not files:
        raise SystemExit(f"no runs under {root / BATCH}")
    kept = {f: (f.read_bytes(), f.stat()) for f in files}
    try:
        for f, (data, _) in kept.items():
            lines = data.decode().splitlines()
            head, last = lines[0].split(","), lines[-1].split(",")
            col = head.index("episode_reward")
            last[col] = repr(float(last[col]) + 1.0)
            f.write_text("\n".join([*lines[:-1], ",".join(last)]) + "\n")
        yield
    finally:
        for f, (data, st) in kept.items():
            f.write_bytes(data)
            os.utime(f, ns=(st.st_atime_ns, st.st_mtime_ns))


def time_command(name: str, args: list[str], folder: str, root: Path, out: Path, extra: list[str]) -> dict:
    """Run ``repro <args>`` on the tree; wall and CPU seconds and peak resident memory (MB)."""
    cmd = [sys.executable, "-m", "repro", *args, "--results", str(root), "--out", str(out / folder), *extra]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # Python's default: compiled modules cached (see the module's doc)
    load = os.getloadavg()[0]
    log = out / f"{name}.log"
    log.parent.mkdir(parents=True, exist_ok=True)
    if name not in KEEPS_CACHE and (out / folder).exists():
        shutil.rmtree(out / folder)  # no cache from an earlier timing
    start = time.perf_counter()
    with log.open("w") as f:
        proc = subprocess.Popen(cmd, env=env, stdout=f, stderr=subprocess.STDOUT)
        _, status, usage = os.wait4(proc.pid, 0)  # this child's own usage (its peak), not the session's
    proc.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - start
    output = log.read_text()
    return {"name": name, "command": "repro " + " ".join(args), "rc": proc.returncode, "wall_s": round(wall, 2),
            "cpu_s": round(usage.ru_utime + usage.ru_stime, 2), "peak_mb": round(usage.ru_maxrss / 1024, 1),
            "load_before": round(load, 2), "tail": output.strip().splitlines()[-3:]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=Path("/tmp/paper-scale"), help="where the tree is written")
    parser.add_argument("--out", type=Path, default=None, help="report folders (default: <root>-out)")
    parser.add_argument("--seeds", type=int, default=6)
    parser.add_argument("--only", action="append", choices=sorted(COMMANDS), help="time only these (repeatable)")
    parser.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    parser.add_argument("extra", nargs="*", help="options passed to every command after --")
    a = parser.parse_args()
    t0 = time.perf_counter()
    runs = write_tree(a.root, a.seeds)
    print(f"tree: {runs} runs under {a.root} ({time.perf_counter() - t0:.0f} s)", flush=True)
    out = a.out or a.root.with_name(a.root.name + "-out")
    # the project's modules compiled once, as installing the package compiles them
    subprocess.run([sys.executable, "-m", "compileall", "-q", *(str(REPO / p) for p in PACKAGES)], check=True,
                   stdout=subprocess.DEVNULL)
    timed: list[dict] = []
    results = {"cpu": cpu_model(), "cores": os.cpu_count(), "runs": runs, "scale": PAPER_SCALE, "commands": timed}
    for name in a.only or list(COMMANDS):
        args, folder = COMMANDS[name]
        with changed_batch(a.root) if name == "report-batch" else contextlib.nullcontext():
            r = time_command(name, args, folder, a.root, out, a.extra)
        timed.append(r)
        print(f"{name:<14} {r['command']:<22} rc={r['rc']} wall {r['wall_s']:7.1f} s  cpu {r['cpu_s']:7.1f} s  "
              f"peak {r['peak_mb']:7.1f} MB  (load {r['load_before']})", flush=True)
        if r["rc"]:
            print("\n".join(r["tail"]), flush=True)
    if a.json:
        a.json.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
