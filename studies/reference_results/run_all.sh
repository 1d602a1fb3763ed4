#!/usr/bin/env bash
# The reference-results grid, breadth first (seed 0 of every system, then seeds 1-2; the expensive
# controllers and experts last). Resumable: run it again, every logged run is skipped.
set -u
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
RUN="nice -n 10 python -m satenv.bench.learning run --workers ${WORKERS:-2}"
CHEAP=platoon-pereira2023,platoon-pereira2022,formation-kannan2022-position,formation-kannan2022-collision
for SEEDS in 0 0-2; do
  $RUN --systems $CHEAP --algorithms controller,ppo,mappo,masac,dagger --seeds $SEEDS
  $RUN --systems servicing-pereira2022,cluster-li2022 --algorithms ppo,mappo,masac --seeds $SEEDS
  $RUN --systems servicing-pereira2022 --algorithms controller --seeds 0
done
$RUN --systems cluster-li2022 --algorithms controller --seeds 0
$RUN --systems servicing-pereira2022,cluster-li2022 --algorithms dagger --seeds 0-2
# PPO once more at ten times the budget on the TPLF platoon: does it learn with more?
$RUN --systems platoon-pereira2023 --algorithms ppo --seeds 0-2 --budget 2000000
