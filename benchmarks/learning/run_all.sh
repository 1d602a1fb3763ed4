#!/usr/bin/env bash
# The reference-results grid in the order it was run (cheap systems first); resumable: run it again.
set -u
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
RUN="nice -n 10 python -m benchmarks.learning run --workers ${WORKERS:-2}"
$RUN --systems platoon-pereira2023,platoon-pereira2022,formation-kannan2022-position,formation-kannan2022-collision \
     --algorithms controller,ppo,mappo,masac,dagger --seeds 0-2
$RUN --systems cluster-li2022,servicing-pereira2022 --algorithms ppo,mappo,masac --seeds 0-2
$RUN --systems servicing-pereira2022,cluster-li2022 --algorithms controller --seeds 0
$RUN --systems servicing-pereira2022,cluster-li2022 --algorithms dagger --seeds 0-2
