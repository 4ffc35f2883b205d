"""In-memory ring replay buffer that stores each frame once (uint8) and rebuilds frame stacks by index.

Slot ``i`` holds one frame, the action taken from it, the reward and discount that followed, the id of
its episode and its position in that episode. A stacked observation is the frames at slots
``i-F+1..i``, clamped to the episode's first frame; a sample never crosses an episode boundary.
The storage can live on any torch device (``replay.device=cuda`` on a GPU machine); a sampled batch goes to the
run's device (``sample_device``): from storage on the CPU to a CUDA run through pinned host memory, copied
without blocking the host.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import torch

from repro.data.sizes import replay_bytes


@dataclass
class EpisodeRecord:
    """Where an episode sits in the ring: first slot and number of frames (= transitions + 1)."""

    ep_id: int
    start: int
    frames: int


class ReplayBuffer:
    def __init__(self, capacity: int, frame_shape: tuple[int, int, int], action_dim: int, frame_stack: int,
                 nstep: int, K: int, discount: float, seed: int, device: str | torch.device = "cpu",
                 sample_device: str | torch.device | None = None):
        self.capacity = capacity
        self.frame_shape = frame_shape
        self.action_dim = action_dim
        self.frame_stack = frame_stack
        self.nstep, self.K, self.gamma = nstep, K, discount
        self.horizon = max(nstep, K)
        self.device = torch.device(device)
        # where sampled batches go (the run's device; default: where the frames live)
        self.sample_device = self.device if sample_device is None else torch.device(sample_device)
        if "cuda" in (self.device.type, self.sample_device.type) and not torch.cuda.is_available():
            raise ValueError(f"replay on {self.device}, batches to {self.sample_device}: this machine has no CUDA "
                             "device")
        # pinned host memory for the copies of batches from storage on the CPU to the run's CUDA device
        self.pinned = self.device.type == "cpu" and self.sample_device.type == "cuda"
        self.frames = torch.empty((capacity, *frame_shape), dtype=torch.uint8, device=self.device)
        self.actions = torch.zeros((capacity, action_dim), dtype=torch.float32, device=self.device)
        self.rewards = torch.zeros(capacity, dtype=torch.float32, device=self.device)
        self.discounts = torch.ones(capacity, dtype=torch.float32, device=self.device)
        self.ep_id = np.full(capacity, -1, dtype=np.int64)
        self.pos = np.zeros(capacity, dtype=np.int64)
        self.rng = np.random.default_rng(seed)
        self.cursor = 0  # next slot to write
        self.size = 0  # filled slots
        self.next_ep_id = 0
        self.episodes: list[EpisodeRecord] = []
        self._current: dict | None = None

    # ------------------------------------------------------------------ memory
    def nbytes(self) -> int:
        """Bytes held by the buffer's arrays."""
        tensors = (self.frames, self.actions, self.rewards, self.discounts)
        return sum(t.numel() * t.element_size() for t in tensors) + self.ep_id.nbytes + self.pos.nbytes

    @staticmethod
    def bytes_for(capacity: int, frame_shape: tuple[int, int, int], action_dim: int) -> int:
        """What :meth:`nbytes` is for a buffer of ``capacity`` (allocated in full at construction), without
        building one: uint8 frames, float32 actions, rewards and discounts, int64 episode ids and positions."""
        return replay_bytes(capacity, frame_shape, action_dim)

    def frame_bytes(self) -> int:
        return self.frames.numel() * self.frames.element_size()

    def __len__(self) -> int:
        return self.size

    # ------------------------------------------------------------------ writing
    def _write_frame(self, frame: np.ndarray, ep: int, pos: int) -> int:
        slot = self.cursor
        self.frames[slot] = torch.as_tensor(frame, device=self.device)
        self.actions[slot] = 0.0
        self.rewards[slot] = 0.0
        self.discounts[slot] = 1.0
        self.ep_id[slot] = ep
        self.pos[slot] = pos
        self.cursor = (slot + 1) % self.capacity
        self.size = min(self.size + 1, self.capacity)
        self._drop_overwritten()
        return slot

    def _drop_overwritten(self) -> None:
        while self.episodes:
            rec = self.episodes[0]
            last = (rec.start + rec.frames - 1) % self.capacity
            if self.ep_id[last] != rec.ep_id:
                self.episodes.pop(0)
            else:
                break

    def start_episode(self, frame: np.ndarray) -> None:
        """Store the first frame (3, H, W) of a new episode."""
        if self._current is not None:
            raise RuntimeError("start_episode() called twice without end_episode()")
        ep = self.next_ep_id
        self.next_ep_id += 1
        slot = self._write_frame(frame, ep, 0)
        self.episodes.append(EpisodeRecord(ep, slot, 1))
        self._current = {"ep": ep, "slot": slot, "pos": 0, "frames": [np.asarray(frame)], "actions": [],
                         "rewards": [], "discounts": []}

    def add(self, action: np.ndarray, reward: float, discount: float, next_frame: np.ndarray) -> None:
        """Record the action taken from the last frame, what followed, and the next frame."""
        cur = self._current
        if cur is None:
            raise RuntimeError("add() before start_episode()")
        slot = cur["slot"]
        self.actions[slot] = torch.as_tensor(action, dtype=torch.float32, device=self.device)
        self.rewards[slot] = float(reward)
        self.discounts[slot] = float(discount)
        cur["pos"] += 1
        cur["slot"] = self._write_frame(next_frame, cur["ep"], cur["pos"])
        self.episodes[-1].frames += 1
        cur["frames"].append(np.asarray(next_frame))
        cur["actions"].append(np.asarray(action, dtype=np.float32))
        cur["rewards"].append(float(reward))
        cur["discounts"].append(float(discount))

    def end_episode(self) -> dict[str, np.ndarray]:
        """Close the current episode and return its arrays (for persisting to disk)."""
        cur = self._current
        if cur is None:
            raise RuntimeError("end_episode() without an episode")
        self._current = None
        return {"ep_id": np.array(cur["ep"]), "frames": np.stack(cur["frames"]),
                "actions": np.asarray(cur["actions"], dtype=np.float32).reshape(-1, self.action_dim),
                "rewards": np.asarray(cur["rewards"], dtype=np.float32),
                "discounts": np.asarray(cur["discounts"], dtype=np.float32)}

    def add_episode(self, ep: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """A whole episode (arrays as :meth:`end_episode` returns them), added step by step as the online loop
        adds it; returns :meth:`end_episode`'s arrays."""
        self.start_episode(ep["frames"][0])
        for t in range(len(ep["actions"])):
            self.add(ep["actions"][t], float(ep["rewards"][t]), float(ep["discounts"][t]), ep["frames"][t + 1])
        return self.end_episode()

    # ------------------------------------------------------------------ resume
    def state(self) -> dict:
        """Everything but the frames: enough, with the episode files, to rebuild the buffer exactly."""
        if self._current is not None:
            raise RuntimeError("the buffer can only be checkpointed between episodes")
        return {"cursor": self.cursor, "size": self.size, "next_ep_id": self.next_ep_id,
                "episodes": [[r.ep_id, r.start, r.frames] for r in self.episodes],
                "rng": self.rng.bit_generator.state}

    def restore(self, state: dict, load_episode) -> None:
        """Rebuild from ``state`` and ``load_episode(ep_id) -> arrays`` (as returned by end_episode)."""
        for ep_id, start, n in state["episodes"]:
            data = load_episode(ep_id)
            if len(data["frames"]) != n:
                raise ValueError(f"episode {ep_id} has {len(data['frames'])} frames, checkpoint says {n}")
            slots = (start + np.arange(n)) % self.capacity
            idx = torch.as_tensor(slots, device=self.device)
            self.frames[idx] = torch.as_tensor(data["frames"], device=self.device)
            actions = np.zeros((n, self.action_dim), dtype=np.float32)
            actions[: n - 1] = data["actions"]
            rewards = np.zeros(n, dtype=np.float32)
            rewards[: n - 1] = data["rewards"]
            discounts = np.ones(n, dtype=np.float32)
            discounts[: n - 1] = data["discounts"]
            self.actions[idx] = torch.as_tensor(actions, device=self.device)
            self.rewards[idx] = torch.as_tensor(rewards, device=self.device)
            self.discounts[idx] = torch.as_tensor(discounts, device=self.device)
            self.ep_id[slots] = ep_id
            self.pos[slots] = np.arange(n)
        self.cursor, self.size, self.next_ep_id = state["cursor"], state["size"], state["next_ep_id"]
        # Slots of episodes overwritten before the checkpoint keep ep_id -1 and are never sampled.
        self.episodes = [EpisodeRecord(*rec) for rec in state["episodes"]]
        self.rng.bit_generator.state = state["rng"]

    # ------------------------------------------------------------------ sampling
    def _valid(self, idx: np.ndarray) -> np.ndarray:
        ep = self.ep_id[idx]
        ahead = (idx + self.horizon) % self.capacity
        ok = (ep >= 0) & (self.ep_id[ahead] == ep) & (self.pos[ahead] == self.pos[idx] + self.horizon)
        back = np.minimum(self.pos[idx], self.frame_stack - 1)
        first = (idx - back) % self.capacity
        ok &= (self.ep_id[first] == ep) & (self.pos[first] == self.pos[idx] - back)
        return ok

    def num_valid(self) -> int:
        return int(self._valid(np.arange(self.size)).sum()) if self.size else 0

    def sample_indices(self, batch_size: int) -> np.ndarray:
        """Uniform over the slots from which ``max(nstep, K)`` further steps exist in the same episode."""
        if self.size == 0:
            raise ValueError("cannot sample from an empty replay buffer")
        chosen: list[np.ndarray] = []
        need = batch_size
        for _ in range(1000):
            cand = self.rng.integers(0, self.size, size=max(2 * need, 16))
            cand = cand[self._valid(cand)][:need]
            chosen.append(cand)
            need -= len(cand)
            if need == 0:
                return np.concatenate(chosen)
        raise ValueError("the replay buffer holds no transition with enough steps ahead in its episode")

    def _stack(self, idx: np.ndarray) -> torch.Tensor:
        offsets = np.arange(self.frame_stack - 1, -1, -1)  # oldest first
        back = np.minimum(offsets[None, :], self.pos[idx][:, None])
        slots = torch.as_tensor((idx[:, None] - back) % self.capacity, device=self.device)
        frames = self.frames[slots]  # (B, F, 3, H, W)
        return frames.flatten(1, 2)

    def sample(self, batch_size: int, future_seq: bool = False) -> dict[str, torch.Tensor]:
        """A batch: obs_t, a_t, a_t..a_{t+K-1}, n-step reward and discount, obs_{t+n}, obs_{t+K},
        and the plain sum of the K rewards r_t..r_{t+K-1}; with ``future_seq`` also the observations
        obs_{t+1}..obs_{t+K} as ``future_obs_seq`` (B, K, C, H, W) for multi-step objectives (SPR)."""
        idx = self.sample_indices(batch_size)
        cap = self.capacity
        steps = (idx[:, None] + np.arange(self.horizon)[None, :]) % cap
        steps_t = torch.as_tensor(steps, device=self.device)
        rewards = self.rewards[steps_t]  # (B, H)
        discounts = self.discounts[steps_t]
        ret = torch.zeros(batch_size, device=self.device)
        disc = torch.ones(batch_size, device=self.device)
        for k in range(self.nstep):
            ret = ret + disc * rewards[:, k]
            disc = disc * self.gamma * discounts[:, k]
        batch = {
            "obs": self._stack(idx),
            "action": self.actions[steps_t[:, 0]],
            "action_seq": self.actions[steps_t[:, : self.K]],
            "reward": ret.unsqueeze(1),
            "discount": disc.unsqueeze(1),
            "next_obs": self._stack((idx + self.nstep) % cap),
            "future_obs": self._stack((idx + self.K) % cap),
            "reward_ksum": rewards[:, : self.K].sum(1, keepdim=True),
        }
        if future_seq:
            batch["future_obs_seq"] = torch.stack([self._stack((idx + k) % cap) for k in range(1, self.K + 1)], 1)
        return self._deliver(batch)

    def _deliver(self, batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """``batch`` on the sample device: as it is when that is the storage's, else copied (from pinned host
        memory without blocking when the storage is on the CPU and the run on CUDA)."""
        if self.sample_device == self.device:
            return batch
        if self.pinned:
            return {k: v.pin_memory().to(self.sample_device, non_blocking=True) for k, v in batch.items()}
        return {k: v.to(self.sample_device) for k, v in batch.items()}
