"""Typed schema of the run config: code reads these dataclasses, never raw strings.

The dataclasses give each field its type and, in it, its allowed values (``Annotated[int, Bound(ge=1)]``:
repro/config/bounds.py; checked by repro.config.compose.validate in one loop); its value (and the comment that
explains it) lives in the packaged YAML under repro/conf/ only. A closed set of values is a :class:`Choice` Enum.
"""

from __future__ import annotations

import dataclasses
import enum
import math
import typing
from dataclasses import dataclass
from functools import cache
from typing import Annotated, Any, Optional, TypeVar

from repro.config import alix
from repro.config.bounds import A_NAME, Bound, Text
from repro.config.plugins import (
    LEARNER_GROUP,
    OBJECTIVE_GROUP,
    LearnerSpec,
    ObjectiveSpec,
    PluginError,
    check_spec,
    discover,
)


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
    """The built-in learners' names (``BUILTIN_LEARNERS`` below); ``agent.learner`` takes these and every learner a
    package registers (:func:`learner_names`)."""

    actor_critic = "actor_critic"  # DrQ-v2 / TACO and the representation ablations (online)
    bc = "bc"  # behaviour cloning (offline)
    td3bc = "td3bc"  # TD3+BC on the DrQ-v2 backbone (offline)
    cql = "cql"  # CQL on the DrQ-v2 backbone (offline)
    iql = "iql"  # IQL on the DrQ-v2 backbone (offline)
    dt = "dt"  # Decision Transformer on pixels (offline)
    alix = "alix"  # A-LIX: DrQ-v2 with adaptive local signal mixing in the encoder (online; repro/config/alix.py)


def is_offline(learner: str) -> bool:
    """Whether ``learner`` (an ``agent.learner`` value) trains from a fixed dataset (offline.dataset): its
    registration says so (an unregistered name: offline, as every learner but the online ones)."""
    spec = learner_specs().get(str(learner))
    return spec is None or spec.offline


def learner_sections(learner: str) -> tuple[str, ...]:
    """The dotted config sections a learner alone reads: its own ``agent.<name>`` (when it registers a section)
    and, offline, ``offline``. A learner nobody registers here (a run of a plugin not installed): ``offline``; its
    own section, unknown, is left as its run wrote it."""
    spec = learner_specs().get(str(learner))
    if spec is None:
        return ("offline",)
    return ((f"agent.{spec.name}",) if spec.section is not None else ()) + (("offline",) if spec.offline else ())


# Keys only the online loop reads (repro/train/online_loop.py, the replay it fills); an offline run reads none of them.
ONLINE_LOOP_KEYS = ("train.frames", "train.seed_frames", "train.explore_steps", "train.update_every_steps",
                    "train.eval_every_frames", "train.eval_episodes", "train.checkpoint_every_episodes",
                    "train.save_frames", "replay.capacity")
# The budget of a run: how far it trains, not what it is. A run re-run with a larger budget continues (extends);
# task.frames is the task's default train.frames. Never part of a run's identity.
BUDGET_KEYS = ("train.frames", "task.frames", "offline.updates")


def unread_keys(learner: str) -> tuple[str, ...]:
    """Dotted config keys (sections or leaves) that ``learner`` never reads (issue 24): other learners' sections
    and, for an offline learner, the online loop's keys. Left out of its run's config.yaml and identity."""
    own = learner_sections(learner)
    others = [s for name in learner_specs() for s in learner_sections(name) if s not in own]
    return tuple(dict.fromkeys([*others, *(ONLINE_LOOP_KEYS if is_offline(learner) else ())]))


def budget_key(learner: str) -> str:
    """The config key that is the budget of a run of ``learner``: ``offline.updates`` offline, else ``train.frames``."""
    return "offline.updates" if is_offline(learner) else "train.frames"


class ObjectiveName(Choice):
    """The built-in auxiliary objectives' names (``BUILTIN_OBJECTIVES`` below); the keys of ``agent.objectives`` are
    these and every objective a package registers (:func:`objective_names`)."""

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


class WandbMode(Choice):
    """``runtime.wandb_mode``: where the W&B mirror's run goes."""

    offline = "offline"  # a W&B run folder under {run}/wandb only; nothing leaves the machine (`repro wandb sync`)
    online = "online"  # streamed to the W&B server as the run trains


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


# ``offline.dataset``'s kinds: how `repro dataset make` makes an offline dataset (docs/offline.md), in the paper's
# Table 3 order. ``offline.dataset`` itself stays a string (any dataset name under the results root, or a folder).
# Built with Enum's functional API: a Choice member's name is its value, and ``medium-replay`` is not a Python name
# (``DatasetKind("medium-replay")`` or ``DatasetKind["medium-replay"]`` reads it).
# (mypy takes the call for str's constructor.)
DatasetKind: type[Choice] = Choice(  # type: ignore[call-overload]
    "DatasetKind", [(k, k) for k in ("medium", "medium-replay", "full-replay")])
DATASET_ALIASES = {"replay": "full-replay", "full": "full-replay"}  # the paper's Table 6 prints 'Replay'


def normalize_dataset(name: Any) -> str | None:
    """The one spelling of a dataset name: lower case with '-' (``Medium_replay`` -> ``medium-replay``; Table 6's
    ``Replay`` -> ``full-replay``); None for None, NaN (a missing table cell) or an empty name. A name that is not
    a :data:`DatasetKind` (an imported dataset's) is spelled the same way. Read by the config (Table 6's CQL alpha)
    and by the analysis (a run's, the paper tables' and the audit's dataset)."""
    if name is None or (isinstance(name, float) and math.isnan(name)):
        return None
    text = str(name).strip().lower().replace("_", "-")
    return DATASET_ALIASES.get(text, text) or None


@dataclass
class StdSchedule:
    """Linear decay of the policy std (conf/agent/*.yaml ``stddev_schedule``)."""

    start: float
    end: float
    duration: int
    # the schedule counts step_scale x the step it is called with: 1 online (agent steps); 2 offline, where it
    # is called with the update count and V-D4RL evaluates it at its loop step (update_every_steps 2: 2u)
    step_scale: Annotated[int, Bound(ge=1)]

    def __call__(self, step: int) -> float:
        """Linear interpolation from ``start`` to ``end`` over ``duration`` schedule steps, at schedule step
        ``step_scale * step``."""
        mix = min(max(self.step_scale * step / max(self.duration, 1), 0.0), 1.0)
        return (1.0 - mix) * self.start + mix * self.end


@dataclass
class CQLConfig:
    """CQL's conservative regulariser (Kumar et al. 2020, continuous form); used by learner ``cql``
    (values: conf/agent/shared/cql.yaml)."""

    alpha: Annotated[Optional[float], Bound(ge=0.0)]  # None: Table 6's value for the run's task and dataset
    n_samples: Annotated[int, Bound(ge=1)]
    temperature: Annotated[float, Bound(gt=0.0)]
    importance_sampling: bool
    include_data_in_logsumexp: bool
    clip_policy_samples: bool


@dataclass
class TD3BCConfig:
    """TD3+BC's actor loss (Fujimoto & Gu 2021, eq. 5; V-D4RL's DrQ+BC on the DrQ-v2 backbone; values:
    conf/agent/shared/td3bc.yaml)."""

    alpha: Annotated[float, Bound(ge=0.0)]
    lambda_from: LambdaFrom


@dataclass
class IQLConfig:
    """Implicit Q-learning (Kostrikov et al. 2022; values: conf/agent/shared/iql.yaml)."""

    expectile: Annotated[float, Bound(gt=0.0, lt=1.0)]
    beta: Annotated[float, Bound(ge=0.0)]
    max_weight: Annotated[float, Bound(gt=0.0)]
    value_for_targets: ValueForTargets
    actor_lr_cosine_updates: Annotated[Optional[int], Bound(ge=1)]  # None: a constant actor learning rate
    learned_log_std: bool
    reward_scaling: RewardScaling


@dataclass
class DTConfig:
    """Decision Transformer (Chen et al. 2021, the gym setting of github kzl/decision-transformer; values:
    conf/agent/shared/dt.yaml)."""

    context: Annotated[int, Bound(ge=1)]
    embed_dim: Annotated[int, Bound(ge=1)]
    n_layers: Annotated[int, Bound(ge=1)]
    n_heads: Annotated[int, Bound(ge=1)]
    dropout: Annotated[float, Bound(ge=0.0, lt=1.0)]
    lr: Annotated[float, Bound(gt=0.0)]
    weight_decay: Annotated[float, Bound(ge=0.0)]
    warmup_steps: Annotated[int, Bound(ge=1)]
    grad_clip: Annotated[float, Bound(gt=0.0)]
    batch_size: Annotated[int, Bound(ge=1)]
    rtg_scale: Annotated[float, Bound(gt=0.0)]
    max_timestep: Annotated[int, Bound(ge=1)]
    activation: DTActivation
    init: DTInit
    ff_dropout: bool
    action_pad: float


@dataclass
class SPRParams:
    """``agent.objective_params.spr`` (repro/agent/objectives/spr.py). An objective's parameters are optional in a
    config: a default here is the objective's own (SPR's), used where the agent file gives none (conf/agent/spr.yaml
    writes them all out, with their comments)."""

    # target <- m target + (1 - m) online (1: the target would never move); with augmentation: 0 (a stop-gradient copy)
    momentum: Annotated[float, Bound(ge=0.0, lt=1.0)] = 0.0
    # width of the projection g and predictor q; None: agent.hidden_dim
    projection_dim: Annotated[Optional[int], Bound(ge=1)] = None
    rollout: bool = True  # roll the transition model out over the K actions, a loss at every step


@dataclass
class ATCParams:
    """``agent.objective_params.atc`` (repro/agent/objectives/atc.py); defaults: ATC's on DMControl (as
    :class:`SPRParams`)."""

    momentum: Annotated[float, Bound(ge=0.0, lt=1.0)] = 0.99  # target update rate tau = 0.01 every update
    predictor_hidden: Annotated[int, Bound(ge=1)] = 512  # hidden size of the residual anchor MLP


@dataclass
class AgentConfig:
    """What every learner's agent shares (conf/agent/<agent>.yaml; ``learner`` and ``stddev_schedule.step_scale``
    from conf/config.yaml unless the agent file sets them). A learner's own settings are its registered ``section``,
    composed by its own agent files only (a built-in one's from conf/agent/shared/)."""

    name: Annotated[str, A_NAME]
    learner: str  # a registered learner (learner_names(); checked by repro.config.compose.validate)
    lr: Annotated[float, Bound(gt=0.0, finite=True)]  # an infinite learning rate trains NaN weights
    feature_dim: Annotated[int, Bound(ge=1)]
    hidden_dim: Annotated[int, Bound(ge=1)]
    batch_size: Annotated[int, Bound(ge=1)]
    K: Annotated[int, Bound(ge=1)]
    nstep: Annotated[int, Bound(ge=1)]
    discount: Annotated[float, Bound(ge=0.0, le=1.0)]
    critic_target_tau: Annotated[float, Bound(ge=0.0, le=1.0)]
    stddev_clip: Annotated[float, Bound(ge=0.0)]
    stddev_schedule: StdSchedule
    action_encoder: bool
    latent_action_dim: Annotated[Optional[int], Bound(ge=1)]  # None: from |A| and latent_action_rounding
    latent_action_rounding: LatentRounding
    action_hidden_dim: Annotated[int, Bound(ge=1)]
    reward_target: RewardTarget
    # a registered objective (objective_names()) -> its loss weight (a negative one would maximise that loss)
    objectives: Annotated[dict[str, float], Bound(ge=0, finite=True, each=True, what="a loss weight",
                                                  note="0 disables it")]
    objective_params: dict[str, Any]  # a registered objective -> its parameters (typed by its registered ``params``,
    # checked by repro.config.compose.validate; an objective reads them typed: compose.objective_params)
    compile: bool
    amp: bool
    fast: bool  # agent.fast: repro/agent/fast.py resolves what it turns on
    # and, in the runs of a learner registered with a ``section``, that section as ``agent.<learner>``
    # (compose._structure adds it; the learner reads it with :func:`learner_section`)


@dataclass
class TaskConfig:
    """A task (conf/task/<task>.yaml and the preset it inherits, conf/preset/)."""

    name: Annotated[str, A_NAME]  # and a task file of repro/conf/task/ (checked by repro.config.compose.validate)
    suite: Suite
    preset: Preset
    std_duration: int
    frames: int
    drqv2_batch_size: int


@dataclass
class EnvConfig:
    action_repeat: Annotated[int, Bound(ge=1)]
    frame_stack: Annotated[int, Bound(ge=1)]
    image_size: Annotated[int, Bound(ge=16)]
    distracting_dims: Annotated[int, Bound(ge=0)]
    max_episode_frames: Annotated[Optional[int], Bound(ge=1)]  # None: the suite's own episode length
    camera: Optional[Any]


@dataclass
class TrainConfig:
    frames: Annotated[int, Bound(ge=1)]
    seed_frames: Annotated[int, Bound(ge=0)]
    explore_steps: Annotated[int, Bound(ge=0)]
    update_every_steps: Annotated[int, Bound(ge=1)]
    eval_every_frames: Annotated[int, Bound(ge=1)]
    eval_episodes: Annotated[int, Bound(ge=0)]
    checkpoint_every_episodes: Annotated[int, Bound(ge=1)]  # the loop takes the episode count modulo it
    save_frames: bool
    save_video: bool
    video_every: VideoEvery
    video_size: Annotated[int, Bound(ge=16, even=True)]


@dataclass
class ReplayConfig:
    capacity: Annotated[int, Bound(ge=1)]  # and room for a transition's horizon (compose._check_horizon)
    device: Device


@dataclass
class OfflineConfig:
    """Offline training (a fixed dataset, no environment interaction but evaluation)."""

    dataset: Optional[str]  # a dataset kind (a name) or a folder (checked by repro.config.compose._check_learner)
    updates: Annotated[int, Bound(ge=1)]
    eval_every_updates: Annotated[int, Bound(ge=1)]
    eval_episodes: Annotated[int, Bound(ge=0)]
    checkpoint_every_updates: Annotated[int, Bound(ge=1)]
    log_every_updates: Annotated[int, Bound(ge=1)]


@dataclass
class RuntimeConfig:
    # `runtime.results_root=$UNSET` in a script: the runs would land in the working folder
    results_root: Annotated[str, Text(r"\S", "{key} is empty: name the folder the runs go under (default: runs).")]
    device: Device
    progress: Any
    threads: Optional[int]
    record: bool
    tensorboard: bool
    keep_replay: bool
    wandb: bool
    wandb_mode: WandbMode
    wandb_project: str
    wandb_entity: Optional[str]
    sweep: Optional[str]


@dataclass
class RunConfig:
    """The run config. Fields are types and allowed values only: every value, with its comment, is in the packaged
    YAML (repro/conf/, top level conf/config.yaml), its one source."""

    experiment: Annotated[str, A_NAME]
    variant: Annotated[str, A_NAME]
    seed: Annotated[int, Bound(ge=0)]
    agent: AgentConfig
    task: TaskConfig
    env: EnvConfig
    train: TrainConfig
    replay: ReplayConfig
    offline: OfflineConfig
    runtime: RuntimeConfig


def choice_fields(section: type = RunConfig, prefix: str = "") -> dict[str, type[Choice]]:
    """Dotted config key -> its :class:`Choice` Enum, for every field of ``section`` (and of its sub-sections)
    typed with one; for the whole :class:`RunConfig`, the registered learners' sections (``agent.<learner>``) too."""
    hints = typing.get_type_hints(section)
    out: dict[str, type[Choice]] = {}
    for f in dataclasses.fields(section):
        kind = hints[f.name]
        if isinstance(kind, type) and issubclass(kind, Choice):
            out[prefix + f.name] = kind
        elif isinstance(kind, type) and dataclasses.is_dataclass(kind):
            out.update(choice_fields(kind, f"{prefix}{f.name}."))
    if section is RunConfig and not prefix:
        for spec in learner_specs().values():
            if spec.section is not None:
                out.update(choice_fields(spec.section, f"agent.{spec.name}."))
    return out


# ------------------------------------------------------------------------------------ the registry (one source)
# The built-in learners and objectives, registered as a plugin registers its own (repro/config/plugins.py): each
# names its code by ``factory``, which repro/learners/registry.py and repro/agent/objectives/ import to build their
# tables from these registrations. The allowed values of a learner's own section and of an objective's parameters
# are declared beside their fields (above). Order: the paper's (bench reports, help texts).
BUILTIN_LEARNERS = (
    LearnerSpec(LearnerName.actor_critic.value, offline=False, label="DrQ-v2", named_by_objectives=True,
                factory="repro.agent.agent:Agent"),
    LearnerSpec(LearnerName.bc.value, offline=True, label="BC", factory="repro.learners.bc:BC"),
    LearnerSpec(LearnerName.td3bc.value, offline=True, label="TD3+BC", section=TD3BCConfig,
                factory="repro.learners.td3bc:TD3BC"),
    LearnerSpec(LearnerName.cql.value, offline=True, label="CQL", section=CQLConfig, factory="repro.learners.cql:CQL",
                resolve="repro.config.paper_defaults:resolve_cql_alpha"),
    LearnerSpec(LearnerName.iql.value, offline=True, label="IQL", section=IQLConfig, factory="repro.learners.iql:IQL"),
    LearnerSpec(LearnerName.dt.value, offline=True, label="DT", section=DTConfig, factory="repro.learners.dt:DT"),
    alix.SPEC,  # A-LIX (online; issue 38): its own section agent.alix and factory, declared as a plugin's
)
_WITH_CURL_AND_REWARD = (ObjectiveName.curl.value, ObjectiveName.reward.value)  # TACO's loss: TACO + CURL + reward;
# the Table 2 objectives replace TACO's term and keep the other two
BUILTIN_OBJECTIVES = (
    ObjectiveSpec(ObjectiveName.taco.value, label="TACO", companions=_WITH_CURL_AND_REWARD,
                  factory="repro.agent.objectives.taco:TACOObjective"),
    ObjectiveSpec(ObjectiveName.curl.value, label="CURL", factory="repro.agent.objectives.taco:CURLObjective"),
    ObjectiveSpec(ObjectiveName.reward.value, label="Reward", factory="repro.agent.objectives.taco:RewardObjective"),
    ObjectiveSpec(ObjectiveName.spr.value, label="SPR", companions=_WITH_CURL_AND_REWARD,
                  factory="repro.agent.objectives.spr:SPRObjective", params=SPRParams),
    ObjectiveSpec(ObjectiveName.atc.value, label="ATC", companions=_WITH_CURL_AND_REWARD,
                  factory="repro.agent.objectives.atc:ATCObjective", params=ATCParams),
    ObjectiveSpec(ObjectiveName.driml.value, label="DRIML", companions=_WITH_CURL_AND_REWARD,
                  factory="repro.agent.objectives.driml:DRIMLObjective"),
)
AGENT_FIELDS = frozenset(f.name for f in dataclasses.fields(AgentConfig))


@cache
def learner_specs() -> dict[str, LearnerSpec]:
    """Every registered learner by name: the built-in ones, then the installed plugins' (entry-point group
    ``taco_repro.learners``) by name. PluginError (one line) for a plugin that clashes with one."""
    for spec in BUILTIN_LEARNERS:
        check_spec(spec, f"built-in learner '{spec.name}'")
    specs = {s.name: s for s in BUILTIN_LEARNERS}
    for spec in discover(LEARNER_GROUP, LearnerSpec):
        if spec.name in specs or spec.name in AGENT_FIELDS:
            raise PluginError(f"learner '{spec.name}' ({LEARNER_GROUP}): the name is taken (a built-in learner or an "
                              "agent.* field).")
        specs[spec.name] = spec
    return specs


@cache
def objective_specs() -> dict[str, ObjectiveSpec]:
    """Every registered objective by name: the built-in ones, then the plugins' (``taco_repro.objectives``)."""
    for spec in BUILTIN_OBJECTIVES:
        check_spec(spec, f"built-in objective '{spec.name}'")
    specs = {s.name: s for s in BUILTIN_OBJECTIVES}
    for spec in discover(OBJECTIVE_GROUP, ObjectiveSpec):
        if spec.name in specs:
            raise PluginError(f"objective '{spec.name}' ({OBJECTIVE_GROUP}): the name is taken by a built-in one.")
        specs[spec.name] = spec
    _check_labels(specs, learner_specs())
    return specs


def _check_labels(objectives: dict[str, ObjectiveSpec], learners: dict[str, LearnerSpec]) -> None:
    """PluginError (one line) unless every registered label is its own (a method label is built from them:
    two registrations of one label would name two methods alike) and every objective's ``companions`` are
    registered objectives without companions of their own."""
    seen: dict[str, str] = {}
    tags = [*((s.label, f"learner '{s.name}'") for s in learners.values()),
            *((s.tag, f"objective '{s.name}'") for s in objectives.values())]
    for tag, who in tags:
        if tag in seen:
            raise PluginError(f"{who}: label '{tag}' is already the label of {seen[tag]}.")
        seen[tag] = who
    for spec in objectives.values():
        for other in spec.companions:
            if other not in objectives or objectives[other].companions or other == spec.name:
                raise PluginError(f"objective '{spec.name}': companion '{other}' must be another registered "
                                  "objective without companions of its own.")


def learner_names() -> tuple[str, ...]:
    """The values ``agent.learner`` accepts, built-in first."""
    return tuple(learner_specs())


def objective_names() -> tuple[str, ...]:
    """The keys ``agent.objectives`` accepts, built-in first."""
    return tuple(objective_specs())


def plugin_conf_dirs() -> tuple[str, ...]:
    """The plugins' conf folders (each with an ``agent/`` group), in registration order, once each."""
    specs: list[LearnerSpec | ObjectiveSpec] = [*learner_specs().values(), *objective_specs().values()]
    return tuple(dict.fromkeys(str(s.conf) for s in specs if s.conf is not None))


def section_type(learner: str) -> type | None:
    """The typed section a learner registers as ``agent.<learner>`` (None for a learner without one, or one nobody
    registers)."""
    spec = learner_specs().get(str(learner))
    return None if spec is None else spec.section


S = TypeVar("S")


def learner_section(agent: AgentConfig, kind: type[S]) -> S:
    """A learner's own typed section (``agent.<learner>``, an instance of ``kind``) of a typed agent config."""
    section = vars(agent).get(str(agent.learner))
    if not isinstance(section, kind):
        raise TypeError(f"agent.{agent.learner} is not a {kind.__name__} (is {agent.learner} registered with "
                        f"section={kind.__name__}?)")
    return section
