#!/usr/bin/env bash
# RL fine-tune of a shipped imitation network (satenv ppo --init-actor): METHOD=lagrangian (default)
# is PPO-Lagrangian on the safety cost, METHOD=reward plain PPO on the task's training reward. In
# segments of 500,000 agent-steps: after each segment the run's final/ (its eval.json: the network
# alone on validation seeds 700000-700019) is kept as <out>/kept/<agent-steps>.
# Resumable: run it again, finished segments are skipped.
#   nohup studies/runs/imitation_rl_finetune/run.sh servicing > runs/lag_ft_servicing.out 2>&1 &
#   nohup studies/runs/imitation_rl_finetune/run.sh cluster > runs/lag_ft_cluster.out 2>&1 &
#   METHOD=reward LAST=20000000 nohup studies/runs/imitation_rl_finetune/run.sh cluster > runs/reward_ft_cluster.out 2>&1 &
set -eu
cd "$(dirname "$0")/../../.."
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
PY=${PYTHON:-.venv/bin/python}
case "${1:-}" in
  servicing) TASK=servicing-pereira2022-random; SEED=satenv/training/policies/servicing_pereira2022_tight_teacher ;;
  cluster) TASK=cluster-case1-random; SEED=satenv/training/policies/cluster_li2022_dagger_shield ;;
  *) echo "usage: $0 servicing|cluster" >&2; exit 2 ;;
esac
case "${METHOD:=lagrangian}" in
  lagrangian) FLAG=--lagrangian; OUT=${OUT:-runs/lag_ft_$1} ;;
  reward) FLAG=; OUT=${OUT:-runs/reward_ft_$1} ;;
  *) echo "METHOD must be lagrangian or reward, not '$METHOD'" >&2; exit 2 ;;
esac
SEGMENT=500000
LAST=${LAST:-4000000}
for ((B = SEGMENT; B <= LAST; B += SEGMENT)); do
  [ -d "$OUT/kept/$B" ] && continue
  nice -n 5 "$PY" -m satenv ppo --task "$TASK" --init-actor "$SEED" \
    $FLAG --critic-warmup 500000 --lr 1e-4 --actor-lr 1e-5 --target-kl 0.01 --init-std 0.1 --checkpoint-every 500000 \
    --test-seeds 700000-700019 --eval-baselines '' --seed 0 --no-progress \
    --out-dir "$OUT" --resume --budget "$B"
  mkdir -p "$OUT/kept" && cp -r "$OUT/final" "$OUT/kept/$B"
done
