#!/usr/bin/env bash
# The published robustness boards: per paper system, its training task nominal and under each of its
# registered perturbations (satenv.tasks, satenv.perturbations), on the first 10 test seeds, with the
# system's controller and its shipped learned policy as shipped. The cluster's tube-RDMPC and the servicing
# NMPC run on their QP solvers (solver="rti"; the reproductions keep ipopt): about 30 s and 15 s an episode.
# Resumable: each board continues from its episodes.jsonl (--resume checks every fingerprint).
set -u
cd "$(dirname "$0")/../../.."
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
run() {  # folder task policies
  python -m satenv.bench.scoreboard --scenarios "$2,$2@*" --policies "$3" --seeds 900000-900009 \
      --out "studies/published/robustness/$1" --resume --progress false
  echo "$1 rc=$?"
}
run platoon-pereira2022 platoon-pereira2022-random "dmpc,trained:platoon_pereira2022_dagger_shield"
run platoon-pereira2023 platoon-tplf30-random-cw "dmpc,trained:platoon_tplf_ppo_shield"
run cluster-li2022 cluster-case1-random "tube_rdmpc_rti,trained:cluster_li2022_dagger_shield"
run formation-kannan2022-position formation-kannan2022-position-random "cgmres,trained:formation_position_dagger"
run formation-kannan2022-collision formation-kannan2022-collision-random "cgmres,trained:formation_collision_dagger_terminal"
run servicing-pereira2022 servicing-pereira2022-random "nmpc_rti,trained:servicing_pereira2022_dagger_shield"
