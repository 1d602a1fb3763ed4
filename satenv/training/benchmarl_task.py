"""satenv as a BenchMARL task family (needs the ``marl`` extra).

Every satenv env is a task (``SatenvTask.PLATOON``, ``CLUSTER``, ``SERVICING``, ``FORMATION``)
built on the native TorchRL env (:func:`satenv.torchrl.make_env`): one group ``"agents"``,
continuous actions in ``[-1, 1]``, the global ``state`` for centralised critics (MAPPO, MASAC,
MADDPG). The task config is ``{"env_kwargs": {...}}`` (the env's keyword arguments)::

    task = SatenvTask.PLATOON.get_task({"env_kwargs": {"randomize": True}})
    Experiment(task=task, algorithm_config=MappoConfig.get_from_yaml(), ...).run()

``python -m satenv.training.benchmarl_train`` wraps this with logs, checkpoints and the export to a
satenv policy folder.

BenchMARL's own config route works too: each task has a YAML config under
``satenv/training/conf/task/satenv/<task>.yaml`` (:data:`CONF_DIR`, like BenchMARL's
``conf/task/vmas/*.yaml``); ``SatenvTask.PLATOON.get_from_yaml()`` loads it, importing this module
registers the tasks as ``satenv/<task>`` for :func:`benchmarl.hydra_config.load_experiment_from_hydra`,
and ``python -m satenv.training.benchmarl_task algorithm=mappo task=satenv/platoon`` runs BenchMARL's
Hydra runner (``benchmarl/run.py``) with these configs on its search path (every Hydra override
works: ``task.env_kwargs.randomize=true``, ``experiment.max_n_frames=...``).
"""

from __future__ import annotations

import copy
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from benchmarl.environments import task_config_registry
from benchmarl.environments.common import Task, TaskClass, _read_yaml_config
from torchrl.data import Composite
from torchrl.envs import EnvBase

__all__ = ["CONF_DIR", "SatenvClass", "SatenvTask", "task_for", "main"]

CONF_DIR = Path(__file__).parent / "conf"
"""Hydra config root of satenv's BenchMARL tasks (``task/satenv/<task>.yaml``)."""


class SatenvClass(TaskClass):
    """How BenchMARL builds a satenv task: ``name`` is the env id's stem (``"PLATOON"``)."""

    @property
    def env_id(self) -> str:
        return f"{self.name.lower()}_v0"

    def get_env_fun(self, num_envs: int, continuous_actions: bool, seed: int | None,
                    device: Any) -> Callable[[], EnvBase]:
        from satenv.torchrl import make_env

        if not continuous_actions:
            raise ValueError(f"satenv task {self.name}: actions are continuous; use a continuous-action algorithm")
        unknown = set(self.config) - {"env_kwargs"}
        if unknown:
            raise ValueError(f"satenv task config: unknown key(s) {sorted(unknown)}; expected 'env_kwargs'")
        kwargs = copy.deepcopy(dict(self.config.get("env_kwargs") or {}))
        return lambda: make_env(self.env_id, num_envs, device=device, seed=seed, **kwargs)

    def supports_continuous_actions(self) -> bool:
        return True

    def supports_discrete_actions(self) -> bool:
        return False

    def has_render(self, env: EnvBase) -> bool:
        return False

    def max_steps(self, env: EnvBase) -> int:
        return env.vec.max_steps

    def group_map(self, env: EnvBase) -> dict[str, list[str]]:
        return env.group_map

    def observation_spec(self, env: EnvBase) -> Composite:
        """The agents' observations alone: the per-agent ``safety_cost`` and filter entries beside
        them are not inputs of the networks."""
        spec = env.full_observation_spec_unbatched.clone()
        del spec["state"]
        for key in [k for k in spec["agents"].keys() if k != "observation"]:
            del spec["agents", key]
        return spec

    def state_spec(self, env: EnvBase) -> Composite | None:
        return Composite({"state": env.full_observation_spec_unbatched["state"].clone()})

    def info_spec(self, env: EnvBase) -> Composite | None:
        return None

    def action_spec(self, env: EnvBase) -> Composite:
        return env.full_action_spec_unbatched

    def action_mask_spec(self, env: EnvBase) -> Composite | None:
        return None

    @staticmethod
    def env_name() -> str:
        return "satenv"


class SatenvTask(Task):
    """The satenv tasks (one per env); build one with ``get_task({"env_kwargs": {...}})``."""

    PLATOON = None
    CLUSTER = None
    SERVICING = None
    FORMATION = None

    @staticmethod
    def associated_class():
        return SatenvClass

    def get_from_yaml(self, path: str | None = None) -> TaskClass:
        """The task with its YAML config (default: ``CONF_DIR/task/satenv/<task>.yaml``)."""
        path = path or str(CONF_DIR / "task" / "satenv" / f"{self.name.lower()}.yaml")
        config = {k: v for k, v in _read_yaml_config(path).items() if k != "defaults"}
        return self.get_task(config=config)


task_config_registry.update({f"satenv/{t.name.lower()}": t for t in SatenvTask})


def task_for(env_id: str, env_kwargs: dict[str, Any] | None = None) -> SatenvClass:
    """The task of a satenv env id (``"platoon_v0"``) with ``env_kwargs``."""
    stem = env_id.removesuffix("_v0").upper()
    if stem not in SatenvTask.__members__:
        raise ValueError(f"unknown satenv env id {env_id!r}; expected one of "
                         f"{[f'{m.lower()}_v0' for m in SatenvTask.__members__]}")
    return SatenvTask[stem].get_task({"env_kwargs": dict(env_kwargs or {})})


def main(argv: list[str] | None = None) -> None:
    """BenchMARL's Hydra runner with satenv's task configs on the search path
    (``python -m satenv.training.benchmarl_task algorithm=mappo task=satenv/platoon [overrides]``)."""
    from benchmarl.run import hydra_experiment

    args = list(sys.argv[1:] if argv is None else argv)
    sys.argv = [sys.argv[0], *args, f"hydra.searchpath=[file://{CONF_DIR.resolve()}]"]
    hydra_experiment()


if __name__ == "__main__":
    main()
