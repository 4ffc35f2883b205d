"""The online loop leaves the queued update alone until the environment has stepped (issue 26): in upstream's order
(act, update, step) nothing between ``agent.update`` returning and ``env.step`` waits for the device, so on a GPU
the environment's step and render run while the update's kernels do. The session's tiny TACO run (conftest's
``tiny_taco``) is watched as it trains, on the CPU: every call of the tree's code that would wait for a CUDA device
(``.item()``, ``.cpu()``, ``float(t)``, ..., ``torch.cuda.synchronize``) is an event (helpers.watch_syncs)."""

from __future__ import annotations

import pytest

from helpers import TINY_TACO


@pytest.mark.slow
@pytest.mark.xdist_group(TINY_TACO)
def test_nothing_waits_for_the_update_before_the_environment_steps(tiny_taco_loop_events: list[str]):
    events = tiny_taco_loop_events
    windows, inside = 0, []
    for i, event in enumerate(events):
        if event == "update returned":
            windows += 1
            inside += events[i + 1:events.index("env.step", i)]
    assert windows >= 50  # the run updated (every other agent step past its seed frames)
    assert any(e.startswith("sync") for e in events)  # the watch works: acting and the rows do wait for the device
    assert not inside, inside[:5]
