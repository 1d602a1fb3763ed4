#!/usr/bin/env bash
# The reference grid's lean run (satenv.bench.learning.trainers.train_lean: the same task, variant,
# seed, budgets and validation seeds) with one change, --target-kl 0.02, on the two cells where the
# grid's runs collapsed most after their published checkpoint. Each 2 M agent-step segment's final/
# (eval.json: validation seeds 700000-700019) is kept as <out>/kept/<agent-steps>. Resumable.
#   nohup studies/runs/target_kl_collapse/run.sh > runs/target_kl.out 2>&1 &
set -eu
cd "$(dirname "$0")/../../.."
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
PY=${PYTHON:-.venv/bin/python}
TARGET_KL=0.02
for CELL in platoon-tplf30-random-cw:ippo platoon-pereira2022-rung1-near:ippo; do
  TASK=${CELL%%:*}; VARIANT=${CELL##*:}
  for SEED in 0 1 2 3 4; do
    OUT=runs/target_kl/$TASK/$VARIANT/seed$SEED
    for B in 2000000 4000000 6000000 8000000 10000000; do
      [ -d "$OUT/kept/$B" ] && continue
      nice -n 10 "$PY" -m satenv ppo --task "$TASK" --variant "$VARIANT" --seed "$SEED" --budget "$B" \
        --checkpoint-every 0 --eval-baselines '' --test-seeds 700000-700019 --target-kl "$TARGET_KL" \
        --no-progress --out-dir "$OUT" --resume
      mkdir -p "$OUT/kept" && cp -r "$OUT/final" "$OUT/kept/$B"
    done
  done
done
