"""Does the warm start survive a refit on its OWN DAgger labels? (no new rows, no safety term)

    nice -n 10 env OMP_NUM_THREADS=1 python studies/runs/cluster_li2022_expert_dagger_alone/refit_probe.py [flown|network] [lr ...]

Adam on the imitation loss of the labels that trained it (studies/runs/cluster_case1_dagger/labels,
rounds 0-6), the same step count as one round of the safe-imitation runs (96 batches of 512), at
each learning rate; then the network behind the filter on validation seeds 700000-700002. The
loss is on the flown action (``flown``: the terminal feedback's blend of the network's output, as
satenv.training.safe_imitation fits it) or on the network's own output (``network``: as the DAgger engine,
satenv.training.imitate.regress, trained the warm start).
"""

import json
import sys
from pathlib import Path

import numpy as np
import torch

from satenv import tasks
from satenv.safety import shield
from satenv.scoring import aggregate, run_episodes
from satenv.training.policy import load
from satenv.training.safe_imitation import _env_action, _inputs, _load_prior, terminal_affine

torch.set_num_threads(1)
WARM = Path("satenv/training/policies/cluster_li2022_dagger_shield")
prior = _load_prior(Path("studies/runs/cluster_case1_dagger/labels"))
task = tasks.get("cluster-case1-random")
env = task.make_env()
out = {}
target = sys.argv[1] if len(sys.argv) > 1 else "flown"
for lr in [float(v) for v in (sys.argv[2:] or ["1e-4", "1e-5"])]:
    pol = load(WARM, shielded=False)
    x = _inputs(pol, prior["obs"])
    y = torch.as_tensor(prior["act"]).clamp(-1, 1)
    off, slope = (torch.as_tensor(v, dtype=torch.float32) for v in terminal_affine(pol, prior["obs"], 3))
    gen = torch.Generator().manual_seed(0)
    opt = torch.optim.Adam(pol.actor.parameters(), lr=lr)
    pol.actor.train()
    for _ in range(96):
        j = torch.randint(len(x), (512,), generator=gen)
        out_j = _env_action(pol.actor(x[j]), 1.0)
        flown = off[j] + slope[j] * out_j if target == "flown" else out_j
        loss = ((flown - y[j]) ** 2).sum(-1).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
    pol.actor.eval()
    agg = aggregate(run_episodes(env, shield(pol, env), task.seeds("validation", 3)))
    out[lr] = {k: agg[k] for k in ("success_rate", "final_error_m", "collision_episodes", "interventions_per_agent_step")}
    print(target, lr, "last batch loss", round(loss.item(), 4), json.dumps(out[lr]), flush=True)
