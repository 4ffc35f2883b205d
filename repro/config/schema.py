"""Typed schema of the run config: code reads these dataclasses, never raw strings."""

from __future__ import annotations

import dataclasses
import enum
import typing
from dataclasses import dataclass, field
from typing import Any, Optional


class Choice(str, enum.Enum):
    """A closed set of allowed values of one config field.

    A member is a ``str`` equal to its value, and prints, formats and serialises (JSON, config.yaml) as that
    value. Its name is its value too: OmegaConf reads and writes an Enum field by member name, so a member
    named otherwise would change the YAML.
    """

    def __str__(self) -> str:
        return str(self.value)

    def __format__(self, spec: str) -> str:
        return str(self.value).__format__(spec)

    @classmethod
    def values(cls) -> tuple[str, ...]:
        """The allowed values, in declaration order."""
        return tuple(str(m.value) for m in cls)


class LearnerName(Choice):
    """``agent.learner``: the keys of the learner registry (repro/learners/registry.py checks it at import)."""

    actor_critic = "actor_critic"  # DrQ-v2 / TACO and the representation ablations (online)
    bc = "bc"  # behaviour cloning (offline)
    td3bc = "td3bc"  # TD3+BC on the DrQ-v2 backbone (offline)
    cql = "cql"  # CQL on the DrQ-v2 backbone (offline)
    iql = "iql"  # IQL on the DrQ-v2 backbone (offline)
    dt = "dt"  # Decision Transformer on pixels (offline)


# The learners that train online (in an environment); every other learner trains from offline.dataset.
ONLINE_LEARNERS = frozenset({LearnerName.actor_critic})


def is_offline(learner: str) -> bool:
    """Whether ``learner`` (an ``agent.learner`` value) trains from a fixed dataset (offline.dataset)."""
    return learner not in ONLINE_LEARNERS


class ObjectiveName(Choice):
    """The keys of ``agent.objectives``: the auxiliary objectives (repro/agent/objectives/ checks them at import)."""

    taco = "taco"  # InfoNCE of (z_t, u_t..u_{t+K-1}) against z_{t+K}
    curl = "curl"  # InfoNCE between two augmentations of one observation
    reward = "reward"  # regression of the reward from (z_t, u_t..u_{t+K-1})
    spr = "spr"  # SPR: predict the momentum encoder's future latents (negative cosine)
    atc = "atc"  # ATC: augmented temporal contrast, no actions
    driml = "driml"  # DRIML: InfoNCE of (z_t, a_t) against z_{t+K}


class LatentRounding(Choice):
    """``agent.latent_action_rounding``: the latent action size when ``latent_action_dim`` is null."""

    upstream = "upstream"  # int(1.25 |A|) + 1 (the TACO code)
    paper = "paper"  # ceil(1.25 |A|) (the paper's text)


class RewardTarget(Choice):
    """``agent.reward_target``: what the reward objective regresses."""

    nstep = "nstep"  # the n-step discounted return (upstream)
    ksum = "ksum"  # the sum of the K rewards (paper)


class Device(Choice):
    """``replay.device`` and ``runtime.device``."""

    cpu = "cpu"
    cuda = "cuda"
    auto = "auto"  # cuda when available, else cpu


class VideoEvery(Choice):
    """``train.video_every``: which evaluations get a video."""

    all = "all"  # every evaluation
    last = "last"  # the final evaluation only


class LambdaFrom(Choice):
    """``agent.td3bc.lambda_from``: the Q that TD3+BC's lambda and actor term use."""

    min = "min"  # min(Q1, Q2) (V-D4RL's DrQ+BC)
    q1 = "q1"  # Q1 only (the original TD3+BC paper)


class ValueForTargets(Choice):
    """``agent.iql.value_for_targets``: which V IQL's actor advantage and critic target use."""

    after = "after"  # V after the value step (the JAX code's learner.py)
    before = "before"  # V before it (CORL's iql.py)


class RewardScaling(Choice):
    """``agent.iql.reward_scaling``."""

    none = "none"  # the dataset's rewards as they are (DrQ-v2 / V-D4RL)
    return_range = "return_range"  # x 1000 / (best - worst episode return of the dataset) (the JAX code)


class DTActivation(Choice):
    """``agent.dt.activation``: the feed-forward activation, by its GPT2Config name."""

    relu = "relu"  # Chen et al.'s --activation_function default
    gelu = "gelu"  # erf GELU (CORL)
    gelu_new = "gelu_new"  # tanh-approximated GELU


class DTInit(Choice):
    """``agent.dt.init``: the initialisation of the transformer body."""

    gpt2 = "gpt2"  # N(0, 0.02) weights, zero biases (GPT2PreTrainedModel)
    torch = "torch"  # torch's layer defaults


class Suite(Choice):
    """``task.suite``: the simulator suite of the task."""

    dmc = "dmc"  # dm_control.suite
    manipulation = "manipulation"  # dm_control.manipulation
    metaworld = "metaworld"  # Meta-world


class Preset(Choice):
    """``task.preset``: DrQ-v2's difficulty preset (conf/preset/), which sets the exploration schedule."""

    easy = "easy"
    medium = "medium"
    hard = "hard"


def check_registry(what: str, keys: Any, names: type[Choice]) -> None:
    """Raise ValueError (one line) unless the ``keys`` of a registry are exactly the values of ``names``."""
    keys, allowed = {str(k) for k in keys}, set(names.values())
    if keys != allowed:
        missing, extra = sorted(allowed - keys), sorted(keys - allowed)
        raise ValueError(f"the {what} registry must hold exactly the names of {names.__name__} in "
                         f"repro/config/schema.py; missing: {', '.join(missing) or '-'}; not in the schema: "
                         f"{', '.join(extra) or '-'}")


@dataclass
class StdSchedule:
    start: float = 1.0
    end: float = 0.1
    duration: int = 500_000
    # the schedule counts step_scale x the step it is called with: 1 online (agent steps); 2 offline, where it
    # is called with the update count and V-D4RL evaluates it at its loop step (update_every_steps 2: 2u)
    step_scale: int = 1

    def __call__(self, step: int) -> float:
        """Linear interpolation from ``start`` to ``end`` over ``duration`` schedule steps, at schedule step
        ``step_scale * step``."""
        mix = min(max(self.step_scale * step / max(self.duration, 1), 0.0), 1.0)
        return (1.0 - mix) * self.start + mix * self.end


@dataclass
class CQLConfig:
    """CQL's conservative regulariser (Kumar et al. 2020, continuous form); used by learner ``cql``."""

    alpha: Optional[float] = None  # None: the paper's Table 6 value for the run's task and dataset
    n_samples: int = 10
    temperature: float = 1.0
    importance_sampling: bool = False
    include_data_in_logsumexp: bool = True  # V-D4RL's no-importance-sampling form (ignored with importance sampling)
    clip_policy_samples: bool = True  # V-D4RL: policy samples drawn with sample(clip=stddev_clip)


@dataclass
class TD3BCConfig:
    """TD3+BC's actor loss (Fujimoto & Gu 2021, eq. 5; V-D4RL's DrQ+BC on the DrQ-v2 backbone)."""

    alpha: float = 2.5  # paper section 5.2: 2.5 (no difference in [2, 3])
    # "min": lambda and the Q term from min(Q1, Q2) (V-D4RL's DrQ+BC); "q1": from Q1 only (original paper)
    lambda_from: LambdaFrom = LambdaFrom.min


@dataclass
class IQLConfig:
    """Implicit Q-learning (Kostrikov et al. 2022)."""

    expectile: float = 0.7  # paper (TACO appendix): 0.7
    beta: float = 0.1  # inverse temperature; the TACO paper's 0.1; the IQL reference MuJoCo config uses 3
    max_weight: float = 100.0  # exp(beta * adv) is clipped here (IQL reference code)
    # which V the actor's advantage and the critic's target use: "after" the value step (the JAX code's
    # learner.py, the default) or "before" it (CORL's iql.py)
    value_for_targets: ValueForTargets = ValueForTargets.after
    # None: constant actor learning rate (DrQ-v2); N: cosine decay of the actor's rate to 0 over N updates
    # (the JAX code's opt_decay_schedule "cosine" with max_steps = N)
    actor_lr_cosine_updates: Optional[int] = None
    # False: the DrQ-v2 actor's scheduled std in log pi (DrQ-v2); True: a learned state-independent log-std
    # (the JAX actor: NormalTanhPolicy(state_dependent_std=False, log_std_min=-5), zeros at start)
    learned_log_std: bool = False
    # "none": the dataset's rewards as they are (DrQ-v2 / V-D4RL); "return_range": rewards x 1000 / (best - worst
    # episode return of the dataset), the JAX code's normalize() of locomotion datasets (train_offline.py)
    reward_scaling: RewardScaling = RewardScaling.none


@dataclass
class DTConfig:
    """Decision Transformer (Chen et al. 2021, the gym setting of github kzl/decision-transformer)."""

    context: int = 20
    embed_dim: int = 128
    n_layers: int = 3
    n_heads: int = 1
    dropout: float = 0.1
    lr: float = 1e-4
    weight_decay: float = 1e-4
    warmup_steps: int = 10_000
    grad_clip: float = 0.25
    batch_size: int = 64
    rtg_scale: float = 1e-3  # returns-to-go are multiplied by this (1/1000)
    max_timestep: int = 1000  # size of the learned timestep embedding; episodes must be shorter
    activation: DTActivation = DTActivation.relu  # feed-forward activation (Chen et al.'s default); CORL: gelu
    init: DTInit = DTInit.gpt2  # "gpt2": N(0, 0.02) body weights (GPT2PreTrainedModel); "torch": torch's defaults
    ff_dropout: bool = False  # a dropout after the activation (torch's TransformerEncoderLayer); GPT-2: none
    action_pad: float = -10.0  # value of padded action slots in training windows (Chen et al.'s get_batch)


@dataclass
class AgentConfig:
    name: str = "taco"
    learner: LearnerName = LearnerName.actor_critic
    lr: float = 1e-4
    feature_dim: int = 50
    hidden_dim: int = 1024
    batch_size: int = 1024
    K: int = 3
    nstep: int = 3
    discount: float = 0.99
    critic_target_tau: float = 0.01
    stddev_clip: float = 0.3
    stddev_schedule: StdSchedule = field(default_factory=StdSchedule)
    action_encoder: bool = True
    latent_action_dim: Optional[int] = None
    latent_action_rounding: LatentRounding = LatentRounding.upstream
    action_hidden_dim: int = 64
    reward_target: RewardTarget = RewardTarget.nstep
    objectives: dict[str, float] = field(default_factory=dict)
    objective_params: dict[str, Any] = field(default_factory=dict)
    compile: bool = False
    amp: bool = False
    cql: CQLConfig = field(default_factory=CQLConfig)
    td3bc: TD3BCConfig = field(default_factory=TD3BCConfig)
    iql: IQLConfig = field(default_factory=IQLConfig)
    dt: DTConfig = field(default_factory=DTConfig)


@dataclass
class TaskConfig:
    name: str = "cheetah_run"
    suite: Suite = Suite.dmc
    preset: Preset = Preset.medium
    std_duration: int = 500_000
    frames: int = 3_100_000
    drqv2_batch_size: int = 256


@dataclass
class EnvConfig:
    action_repeat: int = 2
    frame_stack: int = 3
    image_size: int = 84
    distracting_dims: int = 0
    max_episode_frames: Optional[int] = None
    camera: Optional[Any] = None


@dataclass
class TrainConfig:
    frames: int = 3_100_000
    seed_frames: int = 4000
    explore_steps: int = 2000
    update_every_steps: int = 2
    eval_every_frames: int = 10_000
    eval_episodes: int = 10
    checkpoint_every_episodes: int = 1
    save_frames: bool = True
    save_video: bool = False
    video_every: VideoEvery = VideoEvery.all
    video_size: int = 256


@dataclass
class ReplayConfig:
    capacity: int = 1_000_000
    device: Device = Device.cpu


@dataclass
class OfflineConfig:
    """Offline training (a fixed dataset, no environment interaction but evaluation)."""

    dataset: Optional[str] = None
    updates: int = 100_000
    eval_every_updates: int = 10_000
    eval_episodes: int = 10
    checkpoint_every_updates: int = 5_000
    log_every_updates: int = 1_000


@dataclass
class RuntimeConfig:
    results_root: str = "runs"
    device: Device = Device.auto
    progress: Any = "auto"
    threads: Optional[int] = None
    record: bool = False
    tensorboard: bool = False


@dataclass
class RunConfig:
    experiment: str = "default"
    variant: str = "base"
    seed: int = 1
    agent: AgentConfig = field(default_factory=AgentConfig)
    task: TaskConfig = field(default_factory=TaskConfig)
    env: EnvConfig = field(default_factory=EnvConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    replay: ReplayConfig = field(default_factory=ReplayConfig)
    offline: OfflineConfig = field(default_factory=OfflineConfig)
    runtime: RuntimeConfig = field(default_factory=RuntimeConfig)


def choice_fields(section: type = RunConfig, prefix: str = "") -> dict[str, type[Choice]]:
    """Dotted config key -> its :class:`Choice` Enum, for every field of ``section`` (and of its sub-sections)
    typed with one."""
    hints = typing.get_type_hints(section)
    out: dict[str, type[Choice]] = {}
    for f in dataclasses.fields(section):
        kind = hints[f.name]
        if isinstance(kind, type) and issubclass(kind, Choice):
            out[prefix + f.name] = kind
        elif isinstance(kind, type) and dataclasses.is_dataclass(kind):
            out.update(choice_fields(kind, f"{prefix}{f.name}."))
    return out
