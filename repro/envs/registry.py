"""Static table of every task this project runs: what the simulator needs to build it.

Nothing here imports a simulator: the table is plain data so that configs, sweeps and the CLI can
validate task names cheaply. ``tests/test_envs.py`` checks ``action_dim`` against the real environments.
The per-task training settings of the paper (preset, K, nstep, frame budget) live in the task's config file,
``repro/conf/task/<name>.yaml``, their one source.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass

from repro.config.errors import UserError
from repro.config.schema import Suite


@dataclass(frozen=True)
class TaskInfo:
    """One task.

    Attributes:
        name: the project-wide task name (e.g. ``"quadruped_run"``, ``"hammer"``).
        suite: ``"dmc"`` (``dm_control.suite``), ``"manipulation"`` (``dm_control.manipulation``) or
            ``"metaworld"``.
        domain: the suite domain (``"quadruped"``), ``"manipulation"`` for dm_control.manipulation, and
            ``"metaworld"`` for Meta-world.
        task: the name the suite loads (``"run"``, ``"reach_duplo_vision"``, ``"hammer-v3"``).
        action_dim: the true action dimension of the environment.
        camera: the render camera (id or name).
        notes: free text.
    """

    name: str
    suite: Suite
    domain: str
    task: str
    action_dim: int
    camera: int | str
    notes: str = ""


class UnknownTaskError(UserError, KeyError):
    """Raised by :func:`get_task` for a name not in :data:`TASKS`."""

    def __init__(self, name: str, close_matches: list[str]) -> None:
        super().__init__(name)
        self.name = name
        self.close_matches = list(close_matches)

    def __str__(self) -> str:
        hint = f"; did you mean {', '.join(self.close_matches)}?" if self.close_matches else ""
        return f"unknown task {self.name!r}{hint} (known: {', '.join(sorted(TASKS))})"


def _dmc(name: str, action_dim: int, *, notes: str = "") -> TaskInfo:
    """A ``dm_control.suite`` task named ``<domain>_<task>``."""
    domain, task = name.split("_", 1)
    return TaskInfo(
        name=name,
        suite=Suite.dmc,
        domain=domain,
        task=task,
        action_dim=action_dim,
        camera=2 if domain == "quadruped" else 0,
        notes=notes,
    )


def _metaworld(name: str) -> TaskInfo:
    """A Meta-world v3 task, loaded as ``<name>-v3``."""
    return TaskInfo(
        name=name,
        suite=Suite.metaworld,
        domain="metaworld",
        task=f"{name}-v3",
        action_dim=4,
        camera="corner2",
        notes="MT1 train tasks; success in info['success']",
    )


_ALL: list[TaskInfo] = [
    _dmc("quadruped_run", 12, notes="K=1 in the paper; replay buffer 1e5 upstream"),
    _dmc("quadruped_walk", 12),
    _dmc("hopper_hop", 4),
    _dmc("reacher_hard", 2),
    _dmc("walker_run", 6, notes="K=1 in the paper"),
    _dmc("acrobot_swingup", 1),
    _dmc("cheetah_run", 6),
    _dmc("finger_turn_hard", 2),
    _dmc("cartpole_balance", 1, notes="repro verify's task: the DrQ-v2 authors' published curves move most here "
         "in the first 60K frames (sweeps/verify.yaml)"),
    TaskInfo(
        name="manipulator_bring_ball",
        suite=Suite.dmc,
        domain="manipulator",
        task="bring_ball",
        action_dim=5,
        camera=0,
        notes="frame budget 30.1M upstream",
    ),
    TaskInfo(
        name="reach_duplo",
        suite=Suite.manipulation,
        domain="manipulation",
        task="reach_duplo_vision",
        action_dim=9,
        camera="front_close",
        notes="Jaco arm (6 joints + 3 fingers); 10 s episodes (250 control steps)",
    ),
    *(
        _metaworld(n)
        for n in ("hammer", "assembly", "disassemble", "stick-pull", "pick-place-wall", "hand-insert")
    ),
]

TASKS: dict[str, TaskInfo] = {t.name: t for t in _ALL}


def get_task(name: str) -> TaskInfo:
    """Return the :class:`TaskInfo` for ``name``; raise :class:`UnknownTaskError` with close matches."""
    try:
        return TASKS[name]
    except KeyError:
        matches = difflib.get_close_matches(name, list(TASKS), n=3, cutoff=0.6)
        raise UnknownTaskError(name, matches) from None
