#!/usr/bin/env bash
# The reference-results grid over the ladders (satenv.tasks.ladder), cheapest cells first: one grid
# process at a time, one worker, under nice. Resumable: run it again, every logged run is skipped
# (a run killed mid-way trains again from its start; its logged checkpoints are not written twice).
#   nohup studies/reference_results/run_all.sh > studies/reference_results/run_all.out 2>&1 &
set -u
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
PY=${PYTHON:-.venv/bin/python}   # the project venv unless PYTHON names another interpreter
RUN="nice -n 10 $PY -m satenv.bench.learning run --workers 1"
PLATOON=platoon-pereira2023,platoon-pereira2022
FORMATION=formation-kannan2022-position,formation-kannan2022-collision
NO_FILTER="--filter-systems ''"
# 1. A first table in minutes: the first rung of the platoons and formations, lean PPO, 3 M agent-steps
#    (the controllers are evaluated later: 20 episodes of the formation and cluster MPCs take 0.5-3 h).
eval $RUN --systems $PLATOON,$FORMATION --rungs 1 --algorithms ppo --seeds 0-4 --budget 3000000 $NO_FILTER
# 2. The other lean rows on the same cells and budget, then the same on the cluster and servicing.
eval $RUN --systems $PLATOON,$FORMATION --rungs 1 --algorithms ippo,mappo,ppo_lag --seeds 0-4 --budget 3000000 $NO_FILTER
eval $RUN --systems cluster-li2022,servicing-pereira2022 --rungs 1 --algorithms ppo,mappo,ppo_lag --seeds 0-4 --budget 3000000 $NO_FILTER
# 3. The grid at its budgets (10 M agent-steps per RL run), every rung, easiest rungs first.
for RUNG in 1 2 3; do
  $RUN --systems $PLATOON,$FORMATION --rungs $RUNG --algorithms controller,ppo,ippo,mappo,ppo_lag --seeds 0-4
  $RUN --systems cluster-li2022,servicing-pereira2022 --rungs $RUNG --algorithms controller,ppo,ippo,mappo,ppo_lag --seeds 0-4
done
# 4. The slow rows last: MASAC (BenchMARL, 0.25 gradient steps per frame) and DAgger (the experts label).
for RUNG in 1 2 3; do
  $RUN --systems $PLATOON,$FORMATION,cluster-li2022,servicing-pereira2022 --rungs $RUNG --algorithms masac,dagger --seeds 0-4 $NO_FILTER
done
