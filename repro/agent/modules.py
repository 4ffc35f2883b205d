"""What learners share: ``ModuleSet`` (named modules and optimizers: parameter counts, checkpoint state, train
mode) and ``LearnerBase`` (the defaults of the learner protocol's optional hooks)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from types import MappingProxyType

import torch
from torch import nn

from repro.agent.networks import ActionEncoder
from repro.config.schema import AgentConfig


class ModuleSet:
    """Mixin over ``modules()`` and ``optimizers()`` (both by name). Modules named in ``untrained`` (a target
    network) stay in eval mode and are left out of the parameter counts; they are still checkpointed."""

    untrained: tuple[str, ...] = ()
    training: bool = True

    def modules(self) -> dict[str, nn.Module]:
        raise NotImplementedError

    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        raise NotImplementedError

    def parameter_counts(self) -> list[tuple[str, int]]:
        """Trainable parameters per trained module; a parameter shared by two modules counts at the first."""
        return count_parameters({k: m for k, m in self.modules().items() if k not in self.untrained})

    def state_dict(self) -> dict:
        """Plain tensors and containers (checkpoints load with ``weights_only=True``)."""
        return {"modules": {k: m.state_dict() for k, m in self.modules().items()},
                "optimizers": {k: o.state_dict() for k, o in self.optimizers().items()}}

    def load_state_dict(self, state: dict) -> None:
        for k, m in self.modules().items():
            m.load_state_dict(state["modules"][k])
        for k, o in self.optimizers().items():
            o.load_state_dict(state["optimizers"][k])

    def train(self, training: bool = True) -> None:
        self.training = training
        for name, mod in self.modules().items():
            if name not in self.untrained:
                mod.train(training)


class LearnerBase:
    """The defaults of the learner protocol's optional hooks (``repro/agent/protocol.py`` ``Learner``), for a learner
    that does not need them: no auxiliary objectives, no action encoder, ``agent.batch_size`` transitions per
    update, nothing to record in resolved.json and no use for the dataset's returns."""

    cfg: AgentConfig

    @property
    def weights(self) -> Mapping[str, float]:
        """The active auxiliary objectives' weights, by name."""
        return MappingProxyType({})

    @property
    def action_encoder(self) -> ActionEncoder | None:
        """TACO's action encoder, when the critic sees latent actions."""
        return None

    @property
    def batch_size(self) -> int:
        """Samples per update (a learner with its own batch size overrides this)."""
        return int(self.cfg.batch_size)

    @property
    def resolved(self) -> dict[str, object]:
        """Values this learner used that analysis reads (recorded in resolved.json), beyond the config's."""
        return {}

    def set_dataset_returns(self, returns: Sequence[float]) -> None:
        """The offline dataset's episode returns (IQL's reward scaling reads them); default: unused."""


def count_parameters(modules: dict[str, torch.nn.Module]) -> list[tuple[str, int]]:
    """Trainable parameters per named module, a parameter shared by two modules counted at the first."""
    rows: list[tuple[str, int]] = []
    seen: set[int] = set()
    for name, mod in modules.items():
        params = [p for p in mod.parameters() if p.requires_grad and id(p) not in seen]
        seen.update(id(p) for p in params)
        rows.append((name, sum(p.numel() for p in params)))
    return rows
