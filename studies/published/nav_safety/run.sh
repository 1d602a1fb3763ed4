#!/usr/bin/env bash
# Safety under navigation error at the size of a safety figure: every shipped policy that flies behind
# the filter, on its training task under nav-0.1m and nav-1m (satenv.perturbations: the policy, the
# filter and the controllers read the estimate; the truth is scored), on the first test seeds: 1,000 for
# the platoons (about 0.1 s an episode), 200 for the cluster and servicing (seconds an episode: the
# budget of one machine). Resumable: each board continues from its episodes.jsonl.
#   bash studies/published/nav_safety/run.sh
set -u
cd "$(dirname "$0")/../../.."
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
run() {  # folder task policy last-seed
  python -m satenv.bench.scoreboard --scenarios "$2@nav-0.1m,$2@nav-1m" --policies "$3" --seeds "900000-$4" \
      --out "studies/published/nav_safety/$1" --resume --progress false
  echo "$1 rc=$?"
}
run platoon-pereira2023 platoon-tplf30-random-cw trained:platoon_tplf_ppo_shield 900999
run platoon-pereira2022 platoon-pereira2022-random trained:platoon_pereira2022_dagger_shield 900999
run cluster-li2022 cluster-case1-random trained:cluster_li2022_dagger_shield 900199
run servicing-pereira2022 servicing-pereira2022-random trained:servicing_pereira2022_dagger_shield 900199
