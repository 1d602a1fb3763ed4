"""Bad inputs of the newest APIs are one clear error naming the field: a perturbation a task's env
lacks, a nested ``reset(indices=...)``, a run config's env id, eval baseline or out_dir, an output
path under a file; ``satenv train --resume`` on a new folder starts it (no error)."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

import satenv
from satenv import perturbations, tasks
from satenv.errors import SatenvError


@pytest.mark.parametrize("name", ["disturbance-x2", "inertia-x1.5"])
def test_a_perturbation_the_task_lacks_names_it_and_the_tasks_perturbations(name):
    task = tasks.training_task("platoon-pereira2023")
    with pytest.raises(perturbations.PerturbationMismatchError) as info:
        perturbations.make_env(task, name)
    message = str(info.value)
    assert repr(name) in message and task.name in message
    assert str(list(task.perturbations)) in message
    assert isinstance(info.value, SatenvError) and isinstance(info.value, ValueError)


def test_every_perturbation_of_a_task_still_builds():
    task = tasks.training_task("platoon-pereira2023")
    for name in task.perturbations:
        env = perturbations.make_env(task, name)
        obs, _ = env.reset(seed=0)
        assert all(np.isfinite(o).all() for o in obs.values())


@pytest.mark.parametrize("indices", [[[0]], [[0, 1]], np.zeros((2, 1), dtype=int)])
def test_a_nested_reset_index_is_refused_and_the_vector_env_stays_usable(indices):
    vec = satenv.make_vec("platoon_v0", 2, seed=0)
    vec.reset(seed=0)
    with pytest.raises(SatenvError, match=r"indices=.*shape"):
        vec.reset(indices=indices)
    obs, _ = vec.reset(indices=[0])
    assert np.isfinite(obs).all()


def test_run_configs_refuse_an_unregistered_env_id_baseline_and_an_out_dir_under_a_file(tmp_path):
    from satenv.training.config import TrainConfig

    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    for kwargs, field in (({"env_id": "nope"}, "env_id"), ({"eval_baselines": ("zero", "nope")}, "eval_baselines"),
                          ({"out_dir": str(a_file)}, "out_dir"), ({"out_dir": str(a_file / "run")}, "out_dir")):
        with pytest.raises(ValueError, match=field):
            TrainConfig(**kwargs)
    TrainConfig(env_id="test_env_base:ToyEnv", eval_baselines=("auto",), out_dir=str(tmp_path / "new" / "run"))


def test_an_output_path_under_a_file_is_an_argument_error(tmp_path):
    from satenv.cliargs import out_file, out_folder

    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    for check in (out_file, out_folder):
        with pytest.raises(argparse.ArgumentTypeError, match="lies under"):
            check(str(a_file / "sub" / "x"))
        assert check(str(tmp_path / "new" / "x")) == tmp_path / "new" / "x"
