"""Replay buffer: frames stored once, stacks rebuilt by index, samples never cross episode boundaries."""

import numpy as np
import pytest
import torch

from repro.data.replay import ReplayBuffer

A = 2


def frame(ep, pos):
    """A 3x4x4 frame whose pixels encode (episode, position)."""
    f = np.zeros((3, 4, 4), dtype=np.uint8)
    f[0] = ep
    f[1] = pos
    return f


def fill(buf, lengths, start_ep=0):
    for i, n in enumerate(lengths):
        ep = start_ep + i
        buf.start_episode(frame(ep, 0))
        for t in range(n):
            buf.add(np.array([ep, t], dtype=np.float32), reward=float(10 * ep + t), discount=1.0,
                    next_frame=frame(ep, t + 1))
        buf.end_episode()


def decode(stack, F=3):
    """(3F,4,4) -> list of (ep, pos) of the stacked frames, oldest first."""
    return [(int(stack[3 * k, 0, 0]), int(stack[3 * k + 1, 0, 0])) for k in range(F)]


@pytest.mark.parametrize("nstep,K", [(3, 3), (1, 3), (3, 1), (2, 5)])
def test_samples_stay_inside_episodes(nstep, K):
    buf = ReplayBuffer(1000, (3, 4, 4), A, frame_stack=3, nstep=nstep, K=K, discount=0.9, seed=0)
    fill(buf, [7, 3, 12, 6])
    h = max(nstep, K)
    batch = buf.sample(512)
    for i in range(512):
        obs = decode(batch["obs"][i].numpy())
        ep, t = obs[-1]
        assert all(e == ep for e, _ in obs)
        assert [p for _, p in obs] == [max(t - 2, 0), max(t - 1, 0), t]  # clamped at the first frame
        assert decode(batch["next_obs"][i].numpy())[-1] == (ep, t + nstep)
        assert decode(batch["future_obs"][i].numpy())[-1] == (ep, t + K)
        np.testing.assert_array_equal(batch["action"][i].numpy(), [ep, t])
        np.testing.assert_array_equal(batch["action_seq"][i].numpy(), [[ep, t + k] for k in range(K)])
        rewards = [10 * ep + t + k for k in range(h)]
        expected = sum(0.9 ** k * rewards[k] for k in range(nstep))
        assert batch["reward"][i].item() == pytest.approx(expected, rel=1e-6)
        assert batch["discount"][i].item() == pytest.approx(0.9 ** nstep, rel=1e-6)
        assert batch["reward_ksum"][i].item() == pytest.approx(sum(rewards[:K]), rel=1e-6)
    # the sampled starts are exactly the valid ones (t + max(nstep, K) <= length): none outside, none missed
    starts = {decode(batch["obs"][i].numpy())[-1] for i in range(512)}
    lengths = {0: 7, 1: 3, 2: 12, 3: 6}
    valid = {(e, t) for e, n in lengths.items() for t in range(n - h + 1)}
    assert starts == valid
    assert buf.num_valid() == len(valid)
    assert (h > 3) == all(e != 1 for e, _ in starts)  # the 3-step episode only fits a horizon of 3


def test_discount_stops_at_terminal():
    buf = ReplayBuffer(100, (3, 4, 4), A, frame_stack=3, nstep=3, K=1, discount=0.5, seed=0)
    buf.start_episode(frame(0, 0))
    for t in range(5):
        buf.add(np.zeros(A, np.float32), reward=1.0, discount=0.0 if t == 3 else 1.0, next_frame=frame(0, t + 1))
    buf.end_episode()
    batch = buf.sample(256)
    # by hand, r + g d_t r' + g^2 d_t d_t+1 r'' and g^3 d_t d_t+1 d_t+2 with g = 0.5 and d_3 = 0 (terminal)
    expected = {0: (1 + 0.5 + 0.25, 0.125), 1: (1 + 0.5 + 0.25, 0.0), 2: (1 + 0.5, 0.0)}
    seen = set()
    for i in range(256):
        t = decode(batch["obs"][i].numpy())[-1][1]
        seen.add(t)
        assert batch["reward"][i].item() == pytest.approx(expected[t][0]), t
        assert batch["discount"][i].item() == expected[t][1], t
    assert seen == set(expected)


def test_ring_wraparound_keeps_samples_valid_and_drops_overwritten_episodes():
    buf = ReplayBuffer(20, (3, 4, 4), A, frame_stack=3, nstep=3, K=3, discount=0.99, seed=1)
    fill(buf, [8, 8, 8, 8])  # 36 frames into 20 slots
    assert len(buf) == 20
    # the last 20 frames written survive: episode 1's last two frames, all of episodes 2 and 3
    written = [(e, p) for e in range(4) for p in range(9)]
    alive = set(written[-20:])
    assert [r.ep_id for r in buf.episodes] == [1, 2, 3]  # episode 0 is gone, episode 1 is partly there
    valid = {(e, t) for e, t in alive if all((e, t + k) in alive for k in range(4)) and (e, max(t - 2, 0)) in alive}
    assert valid == {(e, t) for e in (2, 3) for t in range(6)}
    batch = buf.sample(300)
    starts = set()
    for i in range(300):
        obs = decode(batch["obs"][i].numpy())
        ep, t = obs[-1]
        starts.add((ep, t))
        assert all(e == ep for e, _ in obs)
        assert [p for _, p in obs] == [max(t - 2, 0), max(t - 1, 0), t]
        assert decode(batch["future_obs"][i].numpy())[-1] == (ep, t + 3)
    assert starts == valid


def _held_bytes(obj: object) -> int:
    """Bytes of every array the object holds as an attribute, found by looking, not from a list."""
    total = 0
    for value in vars(obj).values():
        if isinstance(value, np.ndarray):
            total += value.nbytes
        elif isinstance(value, torch.Tensor):
            total += value.numel() * value.element_size()
    return total


def test_memory_is_within_ten_percent_of_raw_frames():
    buf = ReplayBuffer(10_000, (3, 84, 84), 12, frame_stack=3, nstep=3, K=3, discount=0.99, seed=0)
    assert buf.frame_bytes() == 10_000 * 3 * 84 * 84
    # nbytes() must count every array the buffer holds: one added to the buffer but not to nbytes() fails here
    assert buf.nbytes() == _held_bytes(buf)
    assert _held_bytes(buf) <= 1.10 * buf.frame_bytes()


def test_state_restore_reproduces_samples():
    buf = ReplayBuffer(20, (3, 4, 4), A, frame_stack=3, nstep=2, K=3, discount=0.9, seed=5)
    store = {}
    for i, n in enumerate([8, 6, 9, 7]):
        buf.start_episode(frame(i, 0))
        for t in range(n):
            buf.add(np.array([i, t], np.float32), float(t), 1.0, frame(i, t + 1))
        data = buf.end_episode()
        store[int(data["ep_id"])] = data
    state = buf.state()
    other = ReplayBuffer(20, (3, 4, 4), A, frame_stack=3, nstep=2, K=3, discount=0.9, seed=99)
    other.restore(state, lambda ep: store[ep])
    a, b = buf.sample(64), other.sample(64)
    for key in a:
        assert torch.equal(a[key], b[key]), key


def test_empty_or_too_short_buffer_raises_clearly():
    buf = ReplayBuffer(10, (3, 4, 4), A, frame_stack=3, nstep=3, K=3, discount=0.9, seed=0)
    with pytest.raises(ValueError, match="empty"):
        buf.sample(4)
    fill(buf, [2])
    with pytest.raises(ValueError, match="no transition"):
        buf.sample(4)


def test_future_sequence_holds_every_step_up_to_K():
    buf = ReplayBuffer(500, (3, 4, 4), A, frame_stack=3, nstep=1, K=4, discount=0.9, seed=2)
    fill(buf, [9, 7, 11])
    batch = buf.sample(128, future_seq=True)
    assert batch["future_obs_seq"].shape == (128, 4, 9, 4, 4)
    for i in range(128):
        ep, t = decode(batch["obs"][i].numpy())[-1]
        for k in range(1, 5):
            stack = decode(batch["future_obs_seq"][i, k - 1].numpy())
            assert stack[-1] == (ep, t + k) and all(e == ep for e, _ in stack)
        assert torch.equal(batch["future_obs_seq"][i, -1], batch["future_obs"][i])
    assert "future_obs_seq" not in buf.sample(4)


def test_add_episode_equals_the_online_loops_step_by_step_fill():
    """add_episode(arrays) stores what start_episode/add/end_episode store (frames, actions, rewards, terminal
    discount), so a buffer filled from a dataset samples what the online loop's buffer samples."""
    stepwise = ReplayBuffer(40, (3, 4, 4), A, frame_stack=3, nstep=2, K=3, discount=0.9, seed=5)
    episodes = []
    for i, n in enumerate([8, 6, 9]):
        stepwise.start_episode(frame(i, 0))
        for t in range(n):
            stepwise.add(np.array([i, -t], np.float32), float(3 * t - i), 0.0 if t == n - 1 and i == 1 else 1.0,
                         frame(i, t + 1))
        episodes.append(stepwise.end_episode())
    whole = ReplayBuffer(40, (3, 4, 4), A, frame_stack=3, nstep=2, K=3, discount=0.9, seed=5)
    for ep in episodes:
        out = whole.add_episode(ep)
        for key in ("frames", "actions", "rewards", "discounts", "ep_id"):
            np.testing.assert_array_equal(out[key], ep[key])
    assert whole.state() == stepwise.state()
    a, b = stepwise.sample(64), whole.sample(64)
    for key in a:
        assert torch.equal(a[key], b[key]), key


def _filled(**devices) -> ReplayBuffer:
    buf = ReplayBuffer(40, (3, 4, 4), A, frame_stack=3, nstep=2, K=3, discount=0.9, seed=5, **devices)
    fill(buf, [8, 6, 9])
    return buf


def test_a_cpu_run_samples_on_the_cpu_without_pinned_memory():
    plain, explicit = _filled(), _filled(device="cpu", sample_device="cpu")
    assert not explicit.pinned and explicit.sample_device == torch.device("cpu")
    a, b = plain.sample(16, future_seq=True), explicit.sample(16, future_seq=True)
    for key in a:
        assert torch.equal(a[key], b[key]) and not b[key].is_pinned() and b[key].device.type == "cpu", key


@pytest.mark.skipif(torch.cuda.is_available(), reason="needs a machine without CUDA")
@pytest.mark.parametrize("devices", [{"device": "cuda"}, {"sample_device": "cuda"}])
def test_cuda_asked_for_on_a_machine_without_it_is_one_clear_error(devices):
    with pytest.raises(ValueError, match="no CUDA device") as err:
        _filled(**devices)
    assert "\n" not in str(err.value)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_samples_are_equal_whether_the_frames_live_on_the_cpu_or_the_gpu():
    on_cpu, to_gpu, on_gpu = _filled(), _filled(sample_device="cuda"), _filled(device="cuda")
    assert to_gpu.pinned and not on_gpu.pinned
    a, b, c = (buf.sample(16, future_seq=True) for buf in (on_cpu, to_gpu, on_gpu))
    for key in a:
        assert b[key].device.type == c[key].device.type == "cuda", key
        assert torch.equal(a[key], b[key].cpu()) and torch.equal(a[key], c[key].cpu()), key
