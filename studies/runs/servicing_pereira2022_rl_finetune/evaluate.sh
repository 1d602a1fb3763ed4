#!/bin/sh
# Both ways on validation seeds of task servicing-pereira2022-random, from the repository root:
#   sh studies/runs/servicing_pereira2022_rl_finetune/evaluate.sh POLICY_FOLDER [EPISODES]
# One JSON line per variant: the network alone (satenv.training.load(..., shielded=False)) and the
# network behind satenv.safety.shield with the shipped folder's margin (0.005), through
# satenv.training.evaluate.evaluate (satenv.scoring.aggregate).
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
nice -n 5 python - "$1" "${2:-10}" <<'PY'
import json, sys, time
from satenv import training
from satenv import tasks
from satenv.safety import shield
from satenv.training.evaluate import evaluate

folder, n = sys.argv[1], int(sys.argv[2])
task = tasks.get("servicing-pereira2022-random")
env = task.make_env()
seeds = list(task.seeds("validation", n))
net = satenv.training.load(folder, env=env, shielded=False)
keys = ("episodes", "success_rate", "collision_episodes", "violation_episodes", "terminated", "steps", "rmse",
        "delta_v", "final_error_m", "min_separation_m", "interventions_per_agent_step", "safety_infeasible",
        "safety_agent_steps")
for variant, pol in (("network alone", net), ("network + filter", shield(net, env, margin=0.005))):
    t0 = time.perf_counter()
    agg = evaluate(env, pol, seeds, progress=False, workers=1)["aggregate"]
    print(json.dumps({"policy": folder, "step": net.meta.get("step"), "variant": variant, "seeds": [seeds[0], seeds[-1]],
                      **{k: agg.get(k) for k in keys}, "wall_s": round(time.perf_counter() - t0, 1)}), flush=True)
PY
