#!/usr/bin/env bash
# The reference-results grid over the ladders (satenv.tasks.ladder), the cells the page's claims need
# first: one grid process at a time, one worker, under nice. Resumable: run it again, every logged run
# is skipped (a run killed mid-way trains again from its start; its logged checkpoints are not written twice).
#   nohup studies/reference_results/run_all.sh > studies/reference_results/run_all.out 2>&1 &
set -u
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
PY=${PYTHON:-.venv/bin/python}   # the project venv unless PYTHON names another interpreter
RUN="nice -n ${NICE:-10} $PY -m satenv.bench.learning run --update-published --workers 1"
PLATOON=platoon-pereira2023,platoon-pereira2022
FORMATION=formation-kannan2022-position,formation-kannan2022-collision
SWARMS=cluster-li2022,servicing-pereira2022
LEAN=ppo,ippo,mappo,ppo_lag
NO_FILTER="--filter-systems ''"
# 1. The targets' cells: PPO on the TPLF training task and on the first rung of every system.
eval $RUN --systems platoon-pereira2023 --rungs 3 --algorithms ppo --seeds 0-4 $NO_FILTER
eval $RUN --systems $PLATOON,$SWARMS,$FORMATION --rungs 1 --algorithms ppo --seeds 0-4 $NO_FILTER
# 2. The grid at its budgets (10 M agent-steps per lean run), rung by rung, easiest first: the lean
#    rows with the filter-in-training row (cluster, servicing, platoon 5.1), then the controllers
#    (20 test episodes of the formation and cluster MPCs take 0.5-3 h).
for RUNG in 1 2 3; do
  $RUN --systems $PLATOON,$SWARMS,$FORMATION --rungs $RUNG --algorithms $LEAN --seeds 0-4
  $RUN --systems $PLATOON,$SWARMS,$FORMATION --rungs $RUNG --algorithms controller
done
# 3. The slow rows last: MASAC (BenchMARL, 0.25 gradient steps per frame) and DAgger (the experts label).
for RUNG in 1 2 3; do
  eval $RUN --systems $PLATOON,$FORMATION,$SWARMS --rungs $RUNG --algorithms masac,dagger --seeds 0-4 $NO_FILTER
done
