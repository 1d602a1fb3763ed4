#!/bin/sh
# PPO fine-tune of the shipped servicing DAgger network in the filtered training env (the filter
# inside the env's step, reward - PENALTY * |du|), from the repository root:
#   sh studies/runs/servicing_pereira2022_rl_finetune/run.sh PENALTY LR OUT_DIR [SAFETY_OPTIONS_JSON [MAX_STEPS [SHAPING_JSON]]]
# (SAFETY_OPTIONS_JSON: the filter's other options, default {}: the defaults, margin 0.02;
# MAX_STEPS: the training episodes' length, default the scenario's 1200; SHAPING_JSON: training-only
# reward shaping, satenv.training.shaping.RewardShaping fields, default {})
# Budgets (agent-steps) doubling; after each, the exported policy is kept as OUT_DIR/ckpt_<budget>.
set -e
P=$1; LR=$2; OUT=$3; SAFETY=${4:-"{}"}; STEPS=${5:-1200}; SHAPING=${6:-"{}"}
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
first=1
for B in 49152 98304 196608 393216; do
  if [ -d "$OUT/ckpt_$B" ]; then first=0; continue; fi   # a restarted script resumes after its last checkpoint
  if [ $first = 1 ]; then
    nice -n 5 python -m satenv.training.train --env-id satenv.bench.learning.trainers:filtered_task_env \
      --env-kwargs "{\"task\": \"servicing-pereira2022-random\", \"penalty\": $P, \"safety\": $SAFETY, \"max_steps\": $STEPS}" \
      --init-actor satenv/training/policies/servicing_pereira2022_dagger_shield --net-arch 512,512,512 \
      --obs-symlog-scale 10 --obs-symlog-dims 6 --log-std-init -1.6 --lr "$LR" --num-envs 16 --n-steps 64 \
      --eval-every 0 --checkpoint-every 49152 --eval-baselines zero --test-seeds 700000 --progress false \
      --reward-shaping "$SHAPING" --budget $B --out-dir "$OUT"
    first=0
  else
    nice -n 5 python -m satenv.training.train --out-dir "$OUT" --resume --allow-code-env-id --budget $B
  fi
  rm -rf "$OUT/ckpt_$B" && cp -r "$OUT/final" "$OUT/ckpt_$B"
  date -u +"%H:%M:%S checkpoint $B done"
done
