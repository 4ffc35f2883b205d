"""``agent.fast`` on CUDA: the whole online update captured once in a CUDA graph and replayed (docs/performance.md).

A training update is about a hundred small kernels (convolutions, a dozen MLPs, four Adam steps); at the sizes of
this agent a GPU spends much of an eager update waiting for Python to launch them. A CUDA graph records the
launches once and replays them with one call. That is possible because ``update()`` makes no host sync (issue 25)
and its shapes never change within a run; what changes from update to update is read from static tensors:

* the batch: copied into buffers of the first batch's keys, shapes and dtypes before every replay;
* the exploration noise's stddev (``agent.stddev_schedule`` at the update's step): a 0-d tensor the backbone reads
  in place of the schedule's value while the graph is recorded (``DrQV2Backbone.fixed_stddev``);
* the random numbers: torch's CUDA generator is registered with the graph, so each replay draws new ones.

The first ``warmup`` updates run eagerly (on a side stream, as CUDA graphs need: they allocate the optimizers'
state and the cuBLAS/cuDNN workspaces), the next one records the graph and every later one replays it. The
optimizers are Adam with ``capturable=True`` (their step counts on the device) and autocast runs without its weight
cache. A graph that cannot be recorded leaves the run eager, with one line on stderr that says why.

The same class runs without a graph (``capture=False``, always on the CPU): the update then reads the static
buffers eagerly, which is how tests/test_graphs.py checks on the CPU that nothing of the update escapes them.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping

import torch

from repro.agent.losses import Metrics

GraphBody = Callable[[dict[str, torch.Tensor], torch.Tensor], Metrics]  # (static batch, static stddev) -> metrics


class GraphedUpdate:
    """``body`` (one update over static inputs) run eagerly ``warmup`` times, then recorded once in a CUDA graph
    and replayed (``capture``: default on a CUDA device only)."""

    def __init__(self, body: GraphBody, device: torch.device | str, warmup: int = 3, capture: bool | None = None):
        self.body = body
        self.device = torch.device(device)
        self.capture = self.device.type == "cuda" if capture is None else capture
        if self.capture and self.device.type != "cuda":
            raise ValueError(f"CUDA graphs need a CUDA device, not {self.device}")
        self.warmup = warmup
        self.calls = 0  # updates made since the last reset
        self.inputs: dict[str, torch.Tensor] = {}
        self.std = torch.zeros((), device=self.device)
        self.graph: torch.cuda.CUDAGraph | None = None
        self.outputs: Metrics = {}
        self.failed: str | None = None  # why the graph could not be recorded (the updates then stay eager)
        # the warm-up updates' stream, made once (PyTorch's recipe: warm up on a side stream before recording)
        self._side = torch.cuda.Stream(self.device) if self.capture else None

    @property
    def replaying(self) -> bool:
        return self.graph is not None

    def __call__(self, batch: Mapping[str, torch.Tensor], std: float) -> Metrics:
        """One update on ``batch`` with exploration stddev ``std``; its metrics (fresh tensors, never the graph's
        own outputs, which the next replay overwrites)."""
        self._stage(batch, std)
        self.calls += 1
        if self.capture and self.graph is None and self.failed is None and self.calls > self.warmup:
            self._record()
        if self.graph is not None:
            self.graph.replay()
            return {k: v.clone() for k, v in self.outputs.items()}
        return self._eager()

    def reset(self) -> None:
        """Forget the graph (after the optimizers' state is replaced, e.g. by a checkpoint's): the next updates
        warm up and record it again."""
        self.graph, self.outputs, self.calls, self.failed = None, {}, 0, None

    # ----------------------------------------------------------------- internals
    def _stage(self, batch: Mapping[str, torch.Tensor], std: float) -> None:
        """Copy ``batch`` and ``std`` into the static inputs (allocated from the first batch)."""
        if not self.inputs:
            self.inputs = {k: torch.empty_like(v, device=self.device) for k, v in batch.items()}
        else:
            wrong = [k for k in set(batch) | set(self.inputs)
                     if k not in batch or k not in self.inputs or batch[k].shape != self.inputs[k].shape
                     or batch[k].dtype != self.inputs[k].dtype]
            if wrong:
                raise ValueError(f"a graphed update needs batches of one layout; {sorted(wrong)} changed")
        for k, v in batch.items():
            self.inputs[k].copy_(v, non_blocking=True)
        self.std.fill_(std)

    def _eager(self) -> Metrics:
        side = self._side
        if side is None:
            return self.body(self.inputs, self.std)
        main = torch.cuda.current_stream(self.device)
        side.wait_stream(main)
        with torch.cuda.stream(side):
            out = self.body(self.inputs, self.std)
        main.wait_stream(side)
        for v in out.values():
            v.record_stream(main)  # read on the main stream after this: not reused by the side stream before
        return out

    def _record(self) -> None:
        graph = torch.cuda.CUDAGraph()
        try:
            with torch.cuda.graph(graph):
                self.outputs = self.body(self.inputs, self.std)
        except (RuntimeError, NotImplementedError, AssertionError) as exc:
            self.failed = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
            self.outputs = {}
            print(f"agent.fast: the update's CUDA graph could not be recorded ({self.failed}); "
                  "the updates stay eager", file=sys.stderr)
            return
        self.graph = graph
