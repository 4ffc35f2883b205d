"""Before/after record of the logs (issue 25): trains a tiny online run (taco) and tiny offline runs (cql_taco,
iql, td3bc, bc; 4 updates, then extended to 8 from the checkpoint) in-process, and prints their train.csv and
eval.csv without the wall-clock columns. Two trees' outputs must be the same bytes:

    PYTHONPATH=<tree> python scripts/log_equality.py <tree> > logs.txt    # <tree>/tests: the dataset fixture
    cmp before.txt after.txt
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import pandas as pd


def main(tree: Path) -> None:
    sys.path.insert(0, str(tree / "tests"))
    from offline_fixtures import write_dataset
    from repro.runs.runformat import OFFLINE_WALLCLOCK_COLUMNS, WALLCLOCK_COLUMNS
    from repro.train import api

    root = Path(tempfile.mkdtemp())
    small = ["task=cheetah_run", "profile=tiny", "env.image_size=32", "agent.feature_dim=16", "agent.hidden_dim=16",
             "runtime.threads=1", f"runtime.results_root={root}"]
    write_dataset(root / "datasets" / "cheetah_run" / "medium", task="cheetah_run", action_dim=6,
                  frame_shape=(3, 32, 32), best_return=200.0)
    offline = ["offline.dataset=medium", "offline.eval_every_updates=3", "offline.eval_episodes=1",
               "offline.checkpoint_every_updates=3", "offline.log_every_updates=3"]
    quiet = lambda s: None  # noqa: E731
    runs = [api.train(small + ["agent=taco", "train.frames=300"], echo=quiet)]
    for agent in ("cql_taco", "iql", "td3bc", "bc"):
        api.train(small + offline + [f"agent={agent}", "offline.updates=4"], echo=quiet)
        runs.append(api.train(small + offline + [f"agent={agent}", "offline.updates=8"], echo=quiet))
    clock = set(WALLCLOCK_COLUMNS) | set(OFFLINE_WALLCLOCK_COLUMNS)
    for run in runs:
        for name in ("train.csv", "eval.csv"):
            df = pd.read_csv(run / name, dtype=str, keep_default_na=False)
            print(f"## {run.relative_to(root)} {name}")
            print(df.drop(columns=[c for c in df.columns if c in clock]).to_csv(index=False))


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(Path(sys.argv[1]))
