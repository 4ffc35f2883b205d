"""The identical inputs of A-LIX's side-by-side check with its authors' code (issue 38).

Shared by ``tests/make_alix_reference.py`` (which runs the authors' code on these inputs and writes
``tests/data/alix_reference.json``) and ``tests/test_alix.py`` (which runs ``repro.agent.alix`` on them and compares).
Both sides start from the same parameters (:func:`initial_value`, a function of our parameter name and its shape;
:data:`AUTHORS_NAME` maps our names to the authors'), update on the same two batches (:func:`batches`) at the same
agent steps, and draw their random numbers (the mixing shifts, the policy noise) from the global torch generator
seeded with :data:`SEED` just before the first update, in the same order.
"""

from __future__ import annotations

import re
import zlib

import numpy as np
import torch

REPO = "Aladoro/Stabilizing-Off-Policy-RL"
COMMIT = "34665c80708bc2703c72906774d2c051e6fb0a28"
FILES = ("drqv2.py", "utils.py", "analysis_layers.py", "analysis_custom_autograd_functions.py", "analysis_utils.py",
         "analysis_modules.py", "analysis_optimizers.py", "cfgs/algo/ALIX.yaml")
OBS_SHAPE = (9, 84, 84)
ACTION_DIM = 6  # cheetah_run's
BATCH = 16
STEPS = (1000, 1002)  # the agent steps of the two updates (update_every_steps 2)
STD_DURATION = 500_000  # the medium preset's: the authors' stddev_schedule 'linear(1.0,0.1,500000)'
SEED = 7  # torch.manual_seed before update 1
SAMPLES = 16  # entries of each parameter recorded after the updates


def authors_name(ours: str) -> str:
    """Our parameter name (``learner.modules()`` key + ``.`` + the module's parameter name) -> the authors' (their
    ``DrQV2Agent`` attribute + ``.`` + parameter name)."""
    if ours == "encoder.strength":
        return "encoder.aug.P"
    m = re.fullmatch(r"encoder\.convnet\.(\d)\.(weight|bias)", ours)
    if m:  # their Sequential holds a mixing layer after each ReLU: convolutions at 0, 3, 6, 9
        return f"encoder.convnet.{int(m.group(1)) // 2 * 3}.{m.group(2)}"
    return ours.replace(".heads.", ".QS.")


def initial_value(name: str, shape: tuple[int, ...]) -> torch.Tensor:
    """The starting value of our parameter ``name``: weights uniform with variance 1/fan_in, biases and LayerNorm
    offsets small, LayerNorm scales near 1, the mixing strength 0.5; drawn from a generator seeded by the name."""
    if name.endswith("strength"):
        return torch.tensor(0.5)
    gen = torch.Generator().manual_seed(zlib.crc32(name.encode()))
    u = torch.rand(shape, generator=gen, dtype=torch.float64) * 2 - 1
    if name.endswith("bias"):
        out = 0.05 * u
    elif len(shape) == 1:  # LayerNorm scale
        out = 1 + 0.1 * u
    else:
        fan_in = shape[1] if ".heads." in name else int(np.prod(shape[1:]))  # (n, in, out) | (out, in, ...)
        out = u * np.sqrt(3.0 / fan_in)
    return out.float()


def batches() -> list[dict[str, np.ndarray]]:
    """The two batches of the two updates: frames (uint8), actions in [-1, 1], rewards in [0, 1], discount
    0.99^3."""
    rng = np.random.default_rng(38)
    out = []
    for _ in STEPS:
        out.append({"obs": rng.integers(0, 256, (BATCH, *OBS_SHAPE), dtype=np.uint8),
                    "next_obs": rng.integers(0, 256, (BATCH, *OBS_SHAPE), dtype=np.uint8),
                    "action": rng.uniform(-1, 1, (BATCH, ACTION_DIM)).astype(np.float32),
                    "reward": rng.uniform(0, 1, (BATCH, 1)).astype(np.float32),
                    "discount": np.full((BATCH, 1), 0.99 ** 3, dtype=np.float32)})
    return out


def sample_index(name: str, numel: int) -> np.ndarray:
    """The flat indices of the entries of parameter ``name`` that are recorded."""
    return np.random.default_rng(zlib.crc32(name.encode())).choice(numel, size=min(SAMPLES, numel), replace=False)


def lix_input() -> torch.Tensor:
    """The feature maps of the mixing layer's own check: (2, 3, 7, 7)."""
    return torch.randn(2, 3, 7, 7, generator=torch.Generator().manual_seed(1), dtype=torch.float64).float()


def rule_gradients() -> dict[str, torch.Tensor]:
    """The incoming gradients of the strength rule's own check: (4, 3, 6, 6), rough and smooth."""
    gen = torch.Generator().manual_seed(2)
    rough = torch.randn(4, 3, 6, 6, generator=gen, dtype=torch.float64).float()
    ramp = torch.arange(6, dtype=torch.float32)
    smooth = (ramp[None, None, :, None] + 0.5 * ramp[None, None, None, :]).expand(4, 3, 6, 6) \
        + 0.01 * rough
    return {"rough": rough, "smooth": smooth.contiguous()}


def our_learner():  # repro.agent.alix.ALIX (imported here: the recording script needs no more of the project)  # noqa: ANN201
    """Our A-LIX learner at the settings of the authors' ALIX.yaml (the packaged agent file) for these inputs."""
    from repro.config.compose import compose, typed
    from repro.learners.registry import build_learner

    cfg = typed(compose(["agent=alix", f"task.std_duration={STD_DURATION}"])).agent
    return build_learner(cfg, OBS_SHAPE, ACTION_DIM, "cpu")


def our_parameters(learner) -> dict[str, torch.nn.Parameter]:  # noqa: ANN001
    """Every parameter of ``learner`` by ``module.parameter`` name, the target critic's included."""
    return {f"{mod}.{k}": p for mod, m in learner.modules().items() for k, p in m.named_parameters()}
