"""Decision Transformer for pixels (Chen et al. 2021; the gym setting of github kzl/decision-transformer).

Each step t of a window contributes three tokens, in this order: return-to-go R_t, state s_t, action a_t.
Every token is a linear embedding plus a learned embedding of the step's timestep (no other position
embedding: Chen et al. removed GPT-2's), then LayerNorm and dropout, then GPT-2 blocks (pre-LayerNorm, a final
LayerNorm, ReLU feed-forward, GPT-2's N(0, 0.02) initialisation; docs/deviations.md, "Offline references"). A
causal mask lets a token see only earlier tokens; a padding mask hides left-padded steps from every real token
(a padded token sees only itself, so no attention row is empty; Chen et al.'s padded tokens see other padded
ones, which changes only outputs at padded steps, never used). The action a_t is predicted from the output at
the state token s_t, which has seen R_<=t, s_<=t and a_<t. States are frame stacks, each through the DrQ-v2
conv Encoder and a linear layer (the Atari DT embeds pixels with a conv encoder the same way). Returns-to-go
are scaled by ``rtg_scale`` (1/1000); at evaluation the target return is scaled the same way and decremented
by each scaled reward.

Also here: ``SequenceSampler`` (windows that never cross an episode boundary, left-padded near an episode's
end, as the reference sampler does), ``EvalContext`` (the history an evaluation episode feeds the model) and
``make_optimizer``. The loss, MSE on the predicted actions of unpadded steps, is ``learners/losses/dt.py``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
import torch
from torch import nn

from repro.agent.networks import Encoder
from repro.config.schema import DTActivation, DTInit

GPT2_INIT_STD = 0.02  # GPT2Config.initializer_range


def activation(name: DTActivation | str) -> nn.Module:
    """The feed-forward activation by its GPT2Config name: ``relu``, ``gelu`` (erf) or ``gelu_new`` (tanh)."""
    if name == DTActivation.relu:
        return nn.ReLU()
    if name == DTActivation.gelu:
        return nn.GELU()
    if name == DTActivation.gelu_new:
        return nn.GELU(approximate="tanh")
    raise ValueError(f"dt.activation must be one of {', '.join(DTActivation)}; got {name!r}")


class GPT2MLP(nn.Module):
    """c_fc, activation, c_proj, dropout (GPT-2's MLP). ``ff_dropout`` adds a dropout right after the
    activation, as torch's TransformerEncoderLayer has (GPT-2 has none there)."""

    def __init__(self, embed_dim: int, act: str, dropout: float, ff_dropout: bool):
        super().__init__()
        self.c_fc = nn.Linear(embed_dim, 4 * embed_dim)
        self.act = activation(act)
        self.act_dropout = nn.Dropout(dropout) if ff_dropout else nn.Identity()
        self.c_proj = nn.Linear(4 * embed_dim, embed_dim)
        self.dropout = nn.Dropout(dropout)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.dropout(self.c_proj(self.act_dropout(self.act(self.c_fc(x)))))


class GPT2Block(nn.Module):
    """GPT-2's pre-LayerNorm block: x + resid_drop(attn(ln_1(x))), then x + mlp(ln_2(x)).

    ``attn``: softmax(q k^T / sqrt(head_dim)) v with dropout on the attention weights (attn_pdrop), then
    the output projection (GPT-2's c_proj); ``resid_dropout`` after it (resid_pdrop).
    """

    def __init__(self, embed_dim: int, n_heads: int, dropout: float, act: str, ff_dropout: bool):
        super().__init__()
        self.ln_1 = nn.LayerNorm(embed_dim)
        self.attn = nn.MultiheadAttention(embed_dim, n_heads, dropout=dropout, batch_first=True)
        self.resid_dropout = nn.Dropout(dropout)
        self.ln_2 = nn.LayerNorm(embed_dim)
        self.mlp = GPT2MLP(embed_dim, act, dropout, ff_dropout)

    def forward(self, x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        y = self.ln_1(x)
        x = x + self.resid_dropout(self.attn(y, y, y, attn_mask=mask, need_weights=False)[0])
        return x + self.mlp(self.ln_2(x))


class GPT2Stack(nn.Module):
    """The GPT-2 body of Chen et al.'s trajectory_gpt2.GPT2Model: blocks ``h`` and the final LayerNorm ``ln_f``;
    no position embedding (their wpe is removed: the timestep embedding is added to every token instead). The
    embedding dropout (GPT-2's ``drop``) is the model's ``embed_drop``."""

    def __init__(self, embed_dim: int, n_layers: int, n_heads: int, dropout: float, act: str,
                 ff_dropout: bool):
        super().__init__()
        self.h = nn.ModuleList([GPT2Block(embed_dim, n_heads, dropout, act, ff_dropout) for _ in range(n_layers)])
        self.ln_f = nn.LayerNorm(embed_dim)

    def forward(self, x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        for block in self.h:
            x = block(x, mask)
        return self.ln_f(x)


def gpt2_init(module: nn.Module) -> None:
    """GPT2PreTrainedModel._init_weights: Linear weights (incl. the attention projections) N(0, 0.02), their
    biases 0, LayerNorm weight 1 and bias 0. Chen et al. apply it to the GPT-2 body only."""
    for m in module.modules():
        if isinstance(m, nn.Linear):
            nn.init.normal_(m.weight, 0.0, GPT2_INIT_STD)
            if m.bias is not None:
                nn.init.zeros_(m.bias)
        elif isinstance(m, nn.MultiheadAttention):
            assert m.in_proj_weight is not None and m.in_proj_bias is not None
            nn.init.normal_(m.in_proj_weight, 0.0, GPT2_INIT_STD)
            nn.init.zeros_(m.in_proj_bias)
        elif isinstance(m, nn.LayerNorm):
            nn.init.ones_(m.weight)
            nn.init.zeros_(m.bias)


class DecisionTransformer(nn.Module):
    """(frames, actions, returns-to-go, timesteps, mask) windows -> predicted actions, (B, K, A).

    Every size and switch comes from the config (``agent.dt``, whose values are Chen et al.'s gym code's):
    ``activation="relu"`` (``--activation_function relu``), GPT-2 blocks (pre-LayerNorm, final LayerNorm,
    ``ff_dropout=False``: no dropout after the activation) with GPT-2's initialisation of the body
    (``init="gpt2"``). ``activation="gelu"`` is CORL's; ``init="torch"`` and ``ff_dropout=True`` give the
    earlier torch-layer model.
    """

    def __init__(self, obs_shape: tuple[int, int, int], action_dim: int, *, context: int, embed_dim: int,
                 n_layers: int, n_heads: int, dropout: float, max_timestep: int, activation: DTActivation | str,
                 init: DTInit | str, ff_dropout: bool):
        super().__init__()
        if init not in tuple(DTInit):
            raise ValueError(f"dt.init must be one of {', '.join(DTInit)}; got {init!r}")
        self.context, self.action_dim, self.n_heads, self.max_timestep = context, action_dim, n_heads, max_timestep
        self.encoder = Encoder(obs_shape)
        self.embed_state = nn.Linear(self.encoder.repr_dim, embed_dim)
        self.embed_return = nn.Linear(1, embed_dim)
        self.embed_action = nn.Linear(action_dim, embed_dim)
        self.embed_timestep = nn.Embedding(max_timestep, embed_dim)
        self.embed_ln = nn.LayerNorm(embed_dim)
        self.embed_drop = nn.Dropout(dropout)
        self.transformer = GPT2Stack(embed_dim, n_layers, n_heads, dropout, activation, ff_dropout)
        if init == DTInit.gpt2:
            gpt2_init(self.transformer)
        self.predict_action = nn.Sequential(nn.Linear(embed_dim, action_dim), nn.Tanh())

    def attention_mask(self, mask: torch.Tensor) -> torch.Tensor:
        """(B * heads, 3K, 3K) boolean, True = may not attend: causal, and padded keys hidden from others."""
        steps = mask.shape[1]
        length = 3 * steps
        real_key = mask.repeat_interleave(3, dim=1)  # (B, 3K): token j belongs to step j // 3
        causal = torch.ones(length, length, dtype=torch.bool, device=mask.device).tril()
        itself = torch.eye(length, dtype=torch.bool, device=mask.device)
        allowed = causal & (real_key[:, None, :] | itself)  # (B, query, key)
        return (~allowed).repeat_interleave(self.n_heads, dim=0)

    def forward(self, frames: torch.Tensor, actions: torch.Tensor, rtg: torch.Tensor, timesteps: torch.Tensor,
                mask: torch.Tensor) -> torch.Tensor:
        """frames (B, K, C, H, W) uint8 or float pixels, actions (B, K, A), rtg (B, K, 1) already scaled,
        timesteps (B, K) int64 < max_timestep, mask (B, K) bool (True = real step). Returns (B, K, A)."""
        batch, steps = mask.shape
        if steps > self.context:
            raise ValueError(f"window of {steps} steps is longer than the context {self.context}")
        dtype = self.embed_state.weight.dtype
        h = self.encoder(frames.reshape(batch * steps, *frames.shape[2:]).to(dtype))
        time = self.embed_timestep(timesteps)
        s = self.embed_state(h).reshape(batch, steps, -1) + time
        r = self.embed_return(rtg.to(dtype)) + time
        a = self.embed_action(actions.to(dtype)) + time
        tokens = interleave(r, s, a)
        x = self.embed_drop(self.embed_ln(tokens))
        x = self.transformer(x, self.attention_mask(mask.bool()))
        state_out = x.reshape(batch, steps, 3, -1)[:, :, 1]
        return self.predict_action(state_out)


def interleave(r: torch.Tensor, s: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
    """Three (B, K, E) token sequences -> (B, 3K, E) in the order R_1 s_1 a_1 R_2 s_2 a_2 ..."""
    batch, steps, width = s.shape
    return torch.stack([r, s, a], dim=2).reshape(batch, 3 * steps, width)


def returns_to_go(rewards: np.ndarray) -> np.ndarray:
    """R_t = sum_{t' >= t} r_t' (undiscounted, to the episode's end), float64."""
    return np.cumsum(np.asarray(rewards, dtype=np.float64)[::-1])[::-1].copy()


def stack_indices(steps: np.ndarray, frame_stack: int) -> np.ndarray:
    """(L, frame_stack) frame indices, oldest first; before the episode start the first frame repeats."""
    return np.maximum(steps[:, None] - np.arange(frame_stack - 1, -1, -1)[None, :], 0)


def left_pad(arrays: Mapping[str, np.ndarray], context: int,
             pad_values: Mapping[str, float] | None = None) -> dict[str, np.ndarray]:
    """Left-pad each (L, ...) array to (context, ...) with its ``pad_values`` entry (0 when absent) and add
    ``mask`` (context,) bool."""
    length = next(iter(arrays.values())).shape[0]
    if not 0 < length <= context:
        raise ValueError(f"window of {length} steps does not fit a context of {context}")
    out: dict[str, np.ndarray] = {}
    for key, value in arrays.items():
        padded = np.full((context,) + value.shape[1:], (pad_values or {}).get(key, 0), dtype=value.dtype)
        padded[context - length:] = value
        out[key] = padded
    out["mask"] = np.arange(context) >= context - length
    return out


def kept_steps(mask: np.ndarray) -> np.ndarray:
    """The flat indices (into the B*K steps, ascending, int64) of the True entries of a (B, K) ``mask``: the
    steps ``losses.dt.action_loss`` averages over (known on the host when the batch is built)."""
    return np.flatnonzero(mask).astype(np.int64)


class SequenceSampler:
    """Random windows of ``context`` steps from episodes, never crossing an episode boundary.

    Episodes are mappings with the Dataset contract's arrays: ``frames`` (T+1, 3, H, W) uint8, ``actions``
    (T, A), ``rewards`` (T,). A window starts at a step drawn uniformly over all steps of all episodes
    (an episode is chosen in proportion to its length) and runs to at most ``context`` steps, stopping at
    the episode's end; shorter windows are left-padded (as kzl/decision-transformer's get_batch: frames, returns
    and timesteps with 0, actions with ``action_pad``, -10 there; the padded steps are masked out).
    ``sample`` returns numpy arrays: ``frames`` (B, K, 3*frame_stack, H, W) uint8, ``actions`` (B, K, A)
    float32, ``rtg`` (B, K, 1) float32 (scaled), ``timesteps`` (B, K) int64, ``mask`` (B, K) bool, ``keep``
    the mask's flat indices (``kept_steps``: the loss gathers with them, without a host sync), plus
    ``episode`` and ``start`` (B,) int64 naming where each window came from. With ``max_timestep`` (the
    model's), an episode too long for the timestep embedding is a one-line ValueError here.
    """

    def __init__(self, episodes: Iterable[Mapping[str, np.ndarray]], *, context: int, frame_stack: int,
                 rtg_scale: float, seed: int, action_pad: float, max_timestep: int | None = None):
        self.context, self.frame_stack, self.rtg_scale = context, frame_stack, rtg_scale
        self.action_pad = float(action_pad)
        self.frames: list[np.ndarray] = []
        self.actions: list[np.ndarray] = []
        self.rtg: list[np.ndarray] = []
        for i, ep in enumerate(episodes):
            frames, actions, rewards = ep["frames"], ep["actions"], ep["rewards"]
            steps = actions.shape[0]
            if steps < 1 or frames.shape[0] != steps + 1 or rewards.shape != (steps,) or actions.ndim != 2:
                raise ValueError(f"episode {i}: need frames (T+1, C, H, W), actions (T, A), rewards (T,) with "
                                 f"T >= 1; got {frames.shape}, {actions.shape}, {rewards.shape}")
            if self.frames and (frames.shape[1:] != self.frames[0].shape[1:]
                                or actions.shape[1] != self.actions[0].shape[1]):
                raise ValueError(f"episode {i}: frame or action shape differs from episode 0")
            self.frames.append(frames)
            self.actions.append(np.asarray(actions, dtype=np.float32))
            self.rtg.append((returns_to_go(rewards) * rtg_scale).astype(np.float32))
        if not self.frames:
            raise ValueError("no episodes to sample from")
        self.lengths = np.array([a.shape[0] for a in self.actions], dtype=np.int64)
        self.offsets = np.concatenate([[0], np.cumsum(self.lengths)])
        self.max_episode_length = int(self.lengths.max())  # the model's max_timestep must be at least this
        if max_timestep is not None and self.max_episode_length > max_timestep:
            raise ValueError(f"an episode has {self.max_episode_length} steps but the timestep embedding only "
                             f"{max_timestep}; raise the model's max_timestep")
        self.rng = np.random.default_rng(seed)

    def window(self, episode: int, start: int) -> dict[str, np.ndarray]:
        """The padded window of ``episode`` starting at step ``start``."""
        end = min(start + self.context, int(self.lengths[episode]))
        steps = np.arange(start, end)
        frames = self.frames[episode][stack_indices(steps, self.frame_stack)]  # (L, fs, C, H, W)
        return left_pad({"frames": frames.reshape(len(steps), -1, *frames.shape[3:]),
                         "actions": self.actions[episode][start:end],
                         "rtg": self.rtg[episode][start:end, None],
                         "timesteps": steps.astype(np.int64)}, self.context, {"actions": self.action_pad})

    def sample(self, batch_size: int) -> dict[str, np.ndarray]:
        flat = self.rng.integers(0, int(self.offsets[-1]), size=batch_size)
        episodes = np.searchsorted(self.offsets, flat, side="right") - 1
        starts = flat - self.offsets[episodes]
        windows = [self.window(int(e), int(s)) for e, s in zip(episodes, starts)]
        batch = {key: np.stack([w[key] for w in windows]) for key in windows[0]}
        batch["keep"] = kept_steps(batch["mask"])
        batch["episode"], batch["start"] = episodes.astype(np.int64), starts.astype(np.int64)
        return batch

    def state_dict(self) -> dict[str, Any]:
        return {"rng": self.rng.bit_generator.state}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        self.rng.bit_generator.state = state["rng"]


class EvalContext:
    """The history of one evaluation episode, as model inputs.

    ``inputs(obs)`` gives the last ``context`` steps ending at the current stacked observation (its action
    slot is a zero placeholder, which the causal mask hides from the prediction at that step);
    ``record(action, reward)`` stores the action taken and decrements the return-to-go by the scaled reward.
    """

    def __init__(self, target_return: float, *, context: int, rtg_scale: float):
        self.context, self.rtg_scale = context, rtg_scale
        self.obs: list[np.ndarray] = []
        self.actions: list[np.ndarray] = []
        self.rtg: list[float] = [target_return * rtg_scale]

    def inputs(self, obs: np.ndarray, action_dim: int) -> dict[str, np.ndarray]:
        if len(self.obs) != len(self.actions):
            raise RuntimeError("record() the previous step's action before the next inputs()")
        self.obs.append(np.asarray(obs))
        start = max(0, len(self.obs) - self.context)
        actions = self.actions[start:] + [np.zeros(action_dim, dtype=np.float32)]
        return left_pad({"frames": np.stack(self.obs[start:]),
                         "actions": np.stack(actions).astype(np.float32),
                         "rtg": np.array(self.rtg[start:], dtype=np.float32)[:, None],
                         "timesteps": np.arange(start, len(self.obs), dtype=np.int64)}, self.context)

    def record(self, action: np.ndarray, reward: float) -> None:
        self.actions.append(np.asarray(action, dtype=np.float32))
        self.rtg.append(self.rtg[-1] - reward * self.rtg_scale)


class LinearWarmup:
    """LR multiplier min((step + 1) / warmup_steps, 1) (the reference's warm-up)."""

    def __init__(self, warmup_steps: int):
        self.warmup_steps = max(int(warmup_steps), 1)

    def __call__(self, step: int) -> float:
        return min((step + 1) / self.warmup_steps, 1.0)


def make_optimizer(model: nn.Module, *, lr: float, weight_decay: float, warmup_steps: int,
                   ) -> tuple[torch.optim.AdamW, torch.optim.lr_scheduler.LambdaLR]:
    """AdamW over all parameters with a linear warm-up; call ``scheduler.step()`` after each update and
    clip gradients (to ``agent.dt.grad_clip``) before ``optimizer.step()``."""
    optimizer = torch.optim.AdamW(model.parameters(), lr=lr, weight_decay=weight_decay)
    return optimizer, torch.optim.lr_scheduler.LambdaLR(optimizer, LinearWarmup(warmup_steps))


def batch_to_tensors(batch: Mapping[str, Any], device: torch.device | str | None = None) -> dict[str, torch.Tensor]:
    """A sampler batch as tensors on ``device`` (frames stay uint8 until the model casts them). To a CUDA device
    host arrays go through pinned memory without blocking, as the replay's batches do (a copy from pageable
    memory would wait for the device's queued work: a host sync in every update)."""
    tensors = {key: torch.as_tensor(value) for key, value in batch.items()}
    target = torch.device(device) if device is not None else None
    if target is None or target.type != "cuda":
        return {key: t.to(target) if target is not None else t for key, t in tensors.items()}
    return {key: (t.pin_memory().to(target, non_blocking=True) if t.device.type == "cpu" else t.to(target))
            for key, t in tensors.items()}
