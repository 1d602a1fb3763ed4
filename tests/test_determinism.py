"""Bitwise determinism across processes and ``PYTHONHASHSEED``.

Sixteen configurations (every env, its presets, dynamics models, randomised initial states and
the scripted baselines including a random and a stochastic one) run a short seeded episode; the
sha256 of every observation, action, reward and info array must be identical in this process and
in two fresh interpreters with different ``PYTHONHASHSEED``.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

STEPS = 12
CONFIGS: list[tuple[str, dict, str, int]] = [
    ("platoon_v0", {}, "dmpc", 0),
    ("platoon_v0", {"preset": "pereira2022"}, "dmpc", 1),
    ("platoon_v0", {"dynamics": "j2", "inclination": 0.9}, "random", 2),
    ("platoon_v0", {"topology": "BDL"}, "zero", 3),
    ("platoon_v0", {"dynamics": "nonlinear"}, "dmpc", 4),
    ("cluster_v0", {}, "apf", 0),
    ("cluster_v0", {"preset": "li2022-case2"}, "apf", 1),
    ("cluster_v0", {"randomize": True}, "random", 2),
    ("cluster_v0", {}, "zero", 3),
    ("servicing_v0", {}, "random", 0),
    ("servicing_v0", {"randomize": True}, "zero", 1),
    ("servicing_v0", {}, "random", 7),
    ("formation_v0", {}, "cgmres", 0),
    ("formation_v0", {"preset": "kannan2022-collision"}, "cgmres", 1),
    ("formation_v0", {"randomize": True}, "random", 2),
    ("formation_v0", {"randomize": True}, "zero", 3),
]


def digests() -> list[str]:
    """One sha256 per configuration of a ``STEPS``-step episode (obs, actions, rewards, infos)."""
    import satenv
    from satenv import baselines

    out = []
    for env_id, kwargs, policy, seed in CONFIGS:
        env = satenv.make(env_id, **kwargs)
        pol = baselines.make(policy, env)
        h = hashlib.sha256()
        obs, info = env.reset(seed=seed)
        pol.reset(seed=seed)
        for _ in range(STEPS):
            act = pol.act(obs)
            obs, rew, _, _, info = env.step(act)
            for d in (obs, act, rew):
                for a in sorted(d):
                    h.update(np.ascontiguousarray(d[a], dtype=np.float64).tobytes())
            for a in sorted(info):
                for k in sorted(info[a]):
                    h.update(np.ascontiguousarray(info[a][k], dtype=np.float64).tobytes())
            if not env.agents:
                break
        out.append(h.hexdigest())
    return out


def test_sixteen_configurations_bitwise_across_processes_and_hash_seeds():
    assert len(CONFIGS) == 16
    here = digests()
    root = Path(__file__).resolve().parents[1]
    code = "import json, test_determinism as t; print(json.dumps(t.digests()))"
    for hash_seed in ("0", "4242"):
        env = {**os.environ, "PYTHONHASHSEED": hash_seed,
               "PYTHONPATH": os.pathsep.join([str(root), str(root / "tests")])}
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                              timeout=300, check=True)
        assert json.loads(proc.stdout.strip().splitlines()[-1]) == here, f"PYTHONHASHSEED={hash_seed}"
    assert len(set(here)) == len(here)   # the configurations really differ
