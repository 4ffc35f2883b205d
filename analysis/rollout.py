"""Random-action rollout frames for F13: ``python -m analysis.rollout OUT_DIR STEPS TASK [TASK ...]``
writes ``OUT_DIR/<task>.npz`` (key ``frames``, uint8 (T, H, W, 3)) for each task in turn.

The caller runs this in its own process: a simulator or OpenGL failure can abort the interpreter, and
the tasks rendered before a failure are kept.
"""

from __future__ import annotations

import sys
from functools import partial
from pathlib import Path

import numpy as np

from repro.runs.fsutil import atomic_write


def rollout(task: str, steps: int = 60) -> np.ndarray:
    """Frames (T, H, W, 3) of ``steps`` uniformly random actions in ``make_env(task, seed=0)``."""
    from repro.envs import make_env

    env = make_env(task, seed=0)
    try:
        rng = np.random.default_rng(0)
        ts = env.reset(seed=0)
        frames = [ts.observation[-3:].transpose(1, 2, 0)]
        for _ in range(steps):
            ts = env.step(rng.uniform(-1, 1, env.spec.action_dim).astype(np.float32))
            frames.append(ts.observation[-3:].transpose(1, 2, 0))
            if ts.last:
                break
        return np.stack(frames).astype(np.uint8)
    finally:
        env.close()


def main(argv: list[str]) -> int:
    out_dir, steps, tasks = Path(argv[0]), int(argv[1]), argv[2:]
    for task in tasks:
        frames = rollout(task, steps)
        atomic_write(out_dir / f"{task}.npz", partial(np.savez_compressed, frames=frames))
        print(f"rendered {task}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
