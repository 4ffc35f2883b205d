"""`repro bench roofline`: where one agent update stands against this machine's own convolution peak.

Everything is measured in this one process (docs/performance.md, "Roofline"):

* the update's FLOPs, counted by torch's FLOP counter (``torch.utils.flop_counter.FlopCounterMode``) over one
  update: convolutions and matrix products forward and backward, which is where the FLOPs are;
* the peak: the FLOP rate of a large fp32 convolution and of the same convolution in bf16 (the encoder's
  32 -> 32 3x3 layer at a large batch), timed here, so "x of peak" mixes no machine with another;
* each path's update time, and the FLOP rate it achieves over its seconds, as a fraction of the peak of the
  dtype its convolutions run in (bf16 under ``agent.amp`` / ``agent.fast`` where they turn it on);
* the kernels: torch's profiler over one update, the ops with the most self time, each with its FLOPs (where the
  profiler counts them) and its achieved rate, so the table says which kernels keep the update from the peak.
"""

from __future__ import annotations

import statistics
from typing import Any

from repro.bench.clock import timed
from repro.bench.results import PATH_FLAGS

PEAK_SHAPE = (256, 32, 41, 41)  # (N, C, H, W) of the peak convolution: the encoder's second layer at batch 256
TOP_KERNELS = 12  # kernels listed per path


def conv_flops(n: int, c_in: int, c_out: int, k: int, h_out: int, w_out: int) -> int:
    """FLOPs of one forward 2-D convolution (a multiply and an add per weight per output element)."""
    return 2 * n * c_out * c_in * k * k * h_out * w_out


def count_flops(fn: Any) -> tuple[int, dict[str, int]]:
    """Total FLOPs of ``fn()`` and the FLOPs per aten op, counted by torch's FLOP counter."""
    from torch.utils.flop_counter import FlopCounterMode

    counter = FlopCounterMode(display=False)
    with counter:
        fn()
    per_op = {str(op): int(n) for op, n in counter.get_flop_counts().get("Global", {}).items()}
    return int(counter.get_total_flops()), per_op


def peak_conv(dtype: str, device: str = "cpu", repeats: int = 3, shape: tuple[int, int, int, int] = PEAK_SHAPE
              ) -> dict[str, Any]:
    """FLOP rate of a large 3x3 convolution in ``dtype`` (float32 | bfloat16): the median of ``repeats`` timed
    runs after one untimed one; the FLOPs are counted, not assumed."""
    import torch

    n, c, h, w = shape
    dt = getattr(torch, dtype)
    g = torch.Generator().manual_seed(0)
    x = torch.randn(shape, generator=g).to(device=device, dtype=dt)
    weight = torch.randn((c, c, 3, 3), generator=g).to(device=device, dtype=dt)

    def run() -> Any:
        return torch.nn.functional.conv2d(x, weight)

    flops, _ = count_flops(run)
    times = [timed(run, device)[1] for _ in range(repeats + 1)][1:]  # the first call warms up
    seconds = statistics.median(times)
    return {"dtype": dtype, "shape": list(shape), "flops": flops, "seconds": round(seconds, 5),
            "gflops_per_s": round(flops / seconds / 1e9, 2)}


def flop_op(kernel: str) -> str | None:
    """The FLOP counter's op (``aten.convolution`` ...) whose FLOPs the profiled kernel ``kernel`` computes: the
    backend convolutions (mkldnn, cudnn, slow_conv) are the forward ``aten.convolution``."""
    name = kernel.removeprefix("aten::")
    if name == "convolution_backward" or name.endswith("convolution_backward"):
        return "aten.convolution_backward"
    if "convolution" in name or name.startswith("slow_conv"):
        return "aten.convolution"
    if name in ("mm", "addmm", "bmm", "baddbmm"):
        return f"aten.{name}"
    return None


def kernel_table(fn: Any, flops_by_op: dict[str, int], top: int = TOP_KERNELS) -> list[dict[str, Any]]:
    """The ops with the most self time in ``fn()`` (torch's profiler): name, calls, self seconds, share of the
    total self time, the FLOPs the counter gave its op (``flops_by_op``; none for memory-bound ops) and the
    achieved GFLOP/s."""
    from torch.profiler import ProfilerActivity, profile

    with profile(activities=[ProfilerActivity.CPU]) as prof:
        fn()
    events = [e for e in prof.key_averages() if e.self_cpu_time_total > 0]
    total = sum(e.self_cpu_time_total for e in events) or 1.0
    owners: dict[str, float] = {}  # self time of all kernels of one counter op: its FLOPs are split by time
    for e in events:
        op = flop_op(e.key)
        if op is not None:
            owners[op] = owners.get(op, 0) + e.self_cpu_time_total
    rows = []
    for e in sorted(events, key=lambda e: e.self_cpu_time_total, reverse=True)[:top]:
        seconds = e.self_cpu_time_total / 1e6
        op = flop_op(e.key)
        flops = int(flops_by_op.get(op, 0) * e.self_cpu_time_total / owners[op]) if op is not None else 0
        rows.append({"op": e.key, "calls": int(e.count), "self_seconds": round(seconds, 5), "flop_op": op,
                     "share": round(e.self_cpu_time_total / total, 4), "flops": flops,
                     "gflops_per_s": round(flops / seconds / 1e9, 2) if flops and seconds else None})
    return rows


def run_roofline(agent: str, batch_size: int, paths: tuple[str, ...], device: str = "cpu", repeats: int = 2,
                 warmup: int = 1, task: str = "cheetah_run", peak_shape: tuple[int, int, int, int] = PEAK_SHAPE,
                 echo: Any = print) -> dict[str, Any]:
    """The roofline of one (agent, batch) update on the plain path and each of ``paths``: FLOPs, seconds (the
    paths alternated update by update, median), the achieved rate against the measured fp32 and bf16 peaks, and
    the kernel table per path."""
    import torch

    from repro.bench.online_update import alternated_times, compose_learner, replay_batch

    agents = {}
    for path in ("plain", *paths):
        agents[path], rc = compose_learner(agent, batch_size, task, device, PATH_FLAGS[path])
    batch = replay_batch(agents["plain"], rc, batch_size, device)

    def update(path: str) -> Any:
        return lambda: agents[path].update(batch, step=10**6)

    times = alternated_times(agents, batch, warmup, repeats, device)  # background load hits every path alike
    peaks = {d: peak_conv(d, device, shape=peak_shape) for d in ("float32", "bfloat16")}
    flops, per_op = count_flops(update("plain"))  # the same ops on every path (FLOPs do not depend on dtype)
    measured = {}
    for path in agents:
        seconds = statistics.median(times[path])
        dtype = "bfloat16" if _runs_bf16(agents[path]) else "float32"
        rate = flops / seconds / 1e9
        measured[path] = {"seconds": round(seconds, 4), "gflops_per_s": round(rate, 2), "conv_dtype": dtype,
                       "of_peak": round(rate / peaks[dtype]["gflops_per_s"], 4),
                       "kernels": kernel_table(update(path), per_op) if device == "cpu" else []}
        echo(f"{agent} B{batch_size} {path}: {seconds:.3f} s/update, {rate:.1f} GFLOP/s = "
             f"{measured[path]['of_peak']:.1%} of this process's {dtype} convolution peak "
             f"({peaks[dtype]['gflops_per_s']:.1f} GFLOP/s)")
    echo(f"{agent} B{batch_size}: {flops / 1e9:.1f} GFLOP per update ({flops / batch_size / 1e9:.3f} per sample), "
         "counted by torch's FLOP counter")
    return {"agent": agent, "batch_size": batch_size, "device": device, "threads": torch.get_num_threads(),
            "flops": flops, "flops_per_sample": flops // batch_size,
            "flops_by_op": dict(sorted(per_op.items(), key=lambda kv: -kv[1])), "peaks": peaks, "paths": measured,
            "repeats": repeats, "warmup": warmup}


def _runs_bf16(agent: Any) -> bool:
    """Whether the agent's convolutions run in bfloat16 (its forward passes under bf16 autocast: ``agent.amp``, or
    the ``agent.fast`` plan it records)."""
    plan = agent.resolved.get("fast") or {}
    return bool(agent.cfg.amp or plan.get("amp", False))
