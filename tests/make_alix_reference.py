"""Write tests/data/alix_reference.json: the A-LIX authors' code run on the inputs of tests/alix_reference.py.

    python tests/make_alix_reference.py --authors DIR

DIR holds the authors' files at the commit of ``alix_reference.COMMIT`` (``alix_reference.FILES`` from
github.com/Aladoro/Stabilizing-Off-Policy-RL, MIT), kept outside this repository: nothing of their code is copied
here, this script imports it from DIR. It builds their ``DrQV2Agent`` as ``cfgs/algo/ALIX.yaml`` configures it
(AllFeatTiedRegularizedEncoder, ParameterizedReg(LocalSignalMixing(pad 2, fixed_batch), 0.5, 'alix_param_grad',
[3, 0.535, 1e-20]), NoShiftAug, custom_parameterized_aug_optimizer_builder(lr 2e-3, betas [0.5, 0.999]), lr 1e-4,
hidden 1024, feature 50, tau 0.01, stddev_clip 0.3), sets the shared starting parameters, runs two updates and
records: the parameter counts of the authors' own initialisation, each update's metrics and the strength's gradient
and value, and after the two updates each parameter's sum, the norm of its change and a sample of its entries; plus
their mixing layer and strength rule alone on small fixed inputs. One CPU thread, float32.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
import alix_reference as ref  # noqa: E402
from repro.runs.rundir import cpu_model  # noqa: E402

TARGET = Path(__file__).parent / "data" / "alix_reference.json"


def build(authors: Path):  # the authors' objects: no project types  # noqa: ANN201
    sys.path.insert(0, str(authors))
    import analysis_layers
    import analysis_modules
    import analysis_optimizers
    import drqv2

    def make() -> object:
        aug = analysis_layers.ParameterizedReg(analysis_layers.LocalSignalMixing(pad=2, fixed_batch=True),
                                               parameter_init=0.5, param_grad_fn="alix_param_grad",
                                               param_grad_fn_args=[3, 0.535, 1e-20])
        encoder = analysis_modules.AllFeatTiedRegularizedEncoder(ref.OBS_SHAPE, aug)
        actor = drqv2.Actor(encoder, (ref.ACTION_DIM,), 50, 1024)
        critic = drqv2.Critic(encoder, (ref.ACTION_DIM,), 50, 1024)
        opt = analysis_optimizers.custom_parameterized_aug_optimizer_builder(encoder_lr=1e-4, lr=2e-3,
                                                                             betas=[0.5, 0.999])
        return drqv2.DrQV2Agent(encoder, actor, critic, ref.OBS_SHAPE, (ref.ACTION_DIM,), "cpu", lr=1e-4,
                                feature_dim=50, hidden_dim=1024, critic_target_tau=0.01, num_expl_steps=2000,
                                update_every_steps=2, stddev_schedule=f"linear(1.0,0.1,{ref.STD_DURATION})",
                                stddev_clip=0.3, use_tb=True, aug=drqv2.NoShiftAug(), encoder_lr=1e-4,
                                actor_lr=1e-4, critic_lr=1e-4, encoder_optimizer_builder=opt)

    return make, analysis_layers, __import__("analysis_custom_autograd_functions")


def params(agent: object) -> dict[str, torch.nn.Parameter]:
    out = {}
    for mod in ("encoder", "actor", "critic", "critic_target"):
        out.update({f"{mod}.{k}": p for k, p in getattr(agent, mod).named_parameters()})
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--authors", type=Path, required=True, help="folder with the authors' files")
    args = parser.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(0)
    make, layers, autograd_fns = build(args.authors.resolve())
    agent = make()
    counts = {mod: sum(p.numel() for p in getattr(agent, mod).parameters()) for mod in ("encoder", "actor", "critic")}

    ours = [(name, tuple(p.shape)) for name, p in ref.our_parameters(ref.our_learner()).items()]
    theirs = params(agent)
    initial = {}
    with torch.no_grad():
        for name, shape in ours:
            their = theirs[ref.authors_name(name)]
            assert tuple(their.shape) == tuple(shape), (name, their.shape, shape)
            value = ref.initial_value(name, tuple(shape))
            if not name.startswith("critic_target."):
                their.copy_(value)
            initial[name] = value
        agent.critic_target.load_state_dict(agent.critic.state_dict())

    torch.manual_seed(ref.SEED)
    batches = ref.batches()
    updates = []
    for step, b in zip(ref.STEPS, batches):
        item = (b["obs"], b["action"], b["reward"], b["discount"], b["next_obs"])
        metrics = agent.update(iter([item]), step)
        P = agent.encoder.aug.P
        updates.append({"metrics": {k: float(v) for k, v in metrics.items() if k != "batch_reward"},
                        "strength_grad": float(P.grad), "strength": float(P.detach())})

    after = {}
    now = params(agent)
    for name, _ in ours:
        value = now[ref.authors_name(name)].detach().double()
        flat = value.flatten().numpy()
        after[name] = {"sum": float(value.sum()), "delta_norm": float((value - initial[name].double()).norm()),
                       "sample": [float(flat[i]) for i in ref.sample_index(name, flat.size)]}

    x = ref.lix_input()
    lix = {}
    for fixed in (True, False):
        layer = layers.LocalSignalMixing(pad=2, fixed_batch=fixed).train()
        torch.manual_seed(3)
        lix["fixed" if fixed else "per_sample"] = layer(x, torch.tensor(0.3)).flatten().tolist()
    rule = {}
    for kind, dy in ref.rule_gradients().items():
        P = torch.nn.Parameter(torch.tensor(0.5))
        inp = torch.zeros_like(dy, requires_grad=True)
        autograd_fns.LearnS.apply(inp, P, 3, 0.535, 1e-20).backward(dy)
        rule[kind] = float(P.grad)

    record = {
        "written_by": "tests/make_alix_reference.py",
        "source": {"repo": ref.REPO, "commit": ref.COMMIT, "files": list(ref.FILES),
                   "note": "the authors' files, run from a folder outside this repository (not copied here)"},
        "inputs": "tests/alix_reference.py (parameters, batches, seeds, steps)",
        "environment": {"torch": torch.__version__, "cpu_capability": torch.backends.cpu.get_cpu_capability(),
                        "cpu": cpu_model(), "machine": platform.machine(), "python": platform.python_version(),
                        "threads": 1, "numpy": np.__version__},
        "parameter_counts": counts,
        "updates": updates,
        "after_two_updates": after,
        "lix": lix,
        "rule": rule,
    }
    TARGET.write_text(json.dumps(record, indent=1) + "\n")
    print(f"wrote {TARGET}")


if __name__ == "__main__":
    main()
