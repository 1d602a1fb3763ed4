"""Ablation (run from the repository root: python studies/runs/cluster_swarm_set_dagger/ablation_mlp.py): an MLP (3 x 256, per-entry
normalisation) fitted from scratch for 45 epochs on the labels of this run's rounds 0-1 and its prior labels
(156,000), with the run's features and terminal feedback; saved to runs/cluster_swarm_mlp_ablation."""
import json
from pathlib import Path

import numpy as np
import torch

from satenv.training.actor import MLPActor
from satenv.training.imitate import features, fit, load_labels, load_saved, with_prior_labels
from satenv.training.policy import LearnedPolicy, ObsNormalizer, save_artifacts, terminal_from_config

run = Path("studies/runs/cluster_swarm_set_dagger")
cfg = load_saved(run / "config.json")
x, y = with_prior_labels(cfg, 47, *load_labels(run, 2))
print("labels", len(x), flush=True)
feats = features(cfg)
torch.manual_seed(cfg.seed)
torch.set_num_threads(1)
actor = MLPActor(feats.out_dim(47), 3, [256, 256, 256], cfg.activation, cfg.squash)
fx = feats(x.astype(np.float64))
norm = ObsNormalizer(fx.mean(0), fx.var(0), cfg.clip_obs)
loss = fit(actor, norm, feats, x, y, cfg, torch.Generator().manual_seed(cfg.seed), cfg.epochs * cfg.round0_epoch_factor)
print("loss", loss, flush=True)
meta = json.loads((run / "rounds/0001/env.json").read_text())
conf = {**json.loads((run / "rounds/0001/config.json").read_text()), "architecture": "mlp"}
pol = LearnedPolicy(actor, norm, obs_shape=(47,), features=feats, meta=meta, terminal=terminal_from_config(conf))
save_artifacts("runs/cluster_swarm_mlp_ablation", pol, env_meta=meta, config=conf, source="ablation: MLP on the set actor's labels")
print("saved", flush=True)
