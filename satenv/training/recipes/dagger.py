"""DAgger of a system's expert on its training task, run until stopped and resumed by the same
command: :mod:`satenv.training.imitate` (the one DAgger engine and its config grammar) under the recipe's
command line.

    nice -n 5 env OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python -m satenv.training.recipes.dagger --system platoon-pereira2022 --run-dir runs/p22/dagger
    nice -n 5 env OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python -m satenv.training.recipes.dagger --system cluster-li2022 --run-dir runs/cluster/dagger

is ``python -m satenv.training.imitate --task <the system's training task> --out-dir <run dir>`` with two
differences: ``--rounds`` defaults to :data:`UNTIL_STOPPED` (choose a round afterwards with
``python -m satenv.training.recipes.ship select``), and a run folder that has a ``config.json`` is resumed
without ``--resume`` (its ``config.json``, of this release or an earlier one; flags given again
override it). Every flag of :class:`satenv.training.imitate.DaggerConfig` is accepted (``--help``);
``--system S`` and ``--run-dir D`` are aliases of ``--task <S's training task>`` and ``--out-dir D``.
"""

from __future__ import annotations

from pathlib import Path

from satenv.training.imitate import (
    SYSTEM_DEFAULTS,
    DaggerConfig,
    Envs,
    collect_episode,
    evaluate,
    features,
    fit,
    label_path,
    load_labels,
    make_envs,
    make_expert,
    plot_curve,
    read_history,
    round_folder,
    run,
    system_config,
)

__all__ = ["SYSTEM_DEFAULTS", "UNTIL_STOPPED", "DaggerConfig", "Envs", "collect_episode", "evaluate", "features",
           "fit", "label_path", "load_labels", "main", "make_envs", "make_expert", "plot_curve", "read_history",
           "round_folder", "run", "system_config"]

UNTIL_STOPPED = 1000
"""This command's default ``--rounds``: more than a run reaches in practice (it is stopped, then a
round is chosen on validation seeds)."""


def main(argv: list[str] | None = None) -> Path | None:
    """``python -m satenv.training.recipes.dagger`` (module docstring)."""
    from satenv.training import imitate

    return imitate.main(argv, prog="python -m satenv.training.recipes.dagger", auto_resume=True,
                        defaults={"--rounds": str(UNTIL_STOPPED)})


if __name__ == "__main__":
    main()
