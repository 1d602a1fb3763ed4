"""Shared test fixtures."""

import multiprocessing

import pytest


@pytest.fixture(autouse=True)
def _keep_multiprocessing_start_method():
    """Importing torchrl sets the process-wide start method to 'spawn'; restore it after the test
    so later tests (the scoreboard's worker processes) run as in a fresh process. Modules that
    need torchrl import it inside their tests, not at collection."""
    before = multiprocessing.get_start_method(allow_none=True)
    yield
    if multiprocessing.get_start_method(allow_none=True) != before:
        multiprocessing.set_start_method(before, force=True)


@pytest.fixture(scope="session")
def docs_site(tmp_path_factory):
    """The documentation site built once per test session, exactly as the README's
    ``mkdocs build --strict`` builds it (into a temporary folder): ``(site folder, build output)``.
    Skips where mkdocs (the ``docs`` extra) is not installed."""
    import importlib.util
    import os
    import subprocess
    import sys
    from pathlib import Path

    if importlib.util.find_spec("mkdocs") is None:
        pytest.skip("mkdocs is not installed (the 'docs' extra: pip install -e '.[docs]')")
    root = Path(__file__).resolve().parent.parent
    site = tmp_path_factory.mktemp("docs") / "site"
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1", "PYTHONPATH": str(root)}
    out = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(site)],
                         cwd=root, capture_output=True, text=True, env=env, timeout=600)
    return site, out


@pytest.fixture
def feedback_policy():
    """A factory of small learned policies for 9-entry observations and 3-axis actions:
    ``feedback_policy(hidden=32, terminal=True)``, a tanh MLP with terminal feedback of radius 2
    (its blend weight is ``exp(-|obs[:3]| / 2)``) unless ``terminal`` is false."""
    def make(hidden: int = 32, terminal: bool = True):
        from satenv.training.actor import MLPActor
        from satenv.training.policy import LearnedPolicy, ObsNormalizer
        from satenv.training.shaping import TerminalFeedback

        return LearnedPolicy(MLPActor(9, 3, [hidden], "tanh", True), ObsNormalizer(), obs_shape=(9,),
                             terminal=TerminalFeedback(radius=2.0) if terminal else None)
    return make


@pytest.fixture
def unconstrained_rows():
    """A factory of ``satenv.training.imitation.fit.fit_safe`` data whose every label is ``label`` and whose
    one filter row per agent-step can never bind: ``unconstrained_rows(obs, label)``."""
    def make(obs, label):
        import numpy as np

        n = len(obs)
        return {"obs": obs, "label": label, "act": label, "filtered": label, "intervened": np.zeros(n, bool),
                "rows": np.zeros((n, 1, 3), np.float32), "lower": np.full((n, 1), -10.0, np.float32)}
    return make


@pytest.fixture
def relu_policy_folder():
    """A factory of policy folders in an imitation network's layout for a task's env:
    ``relu_policy_folder(folder, task, terminal=False)``, a squashed ReLU MLP (16-16, random weights) on
    the observation plus 6 symlog features, behind a random frozen observation normalisation; with
    ``terminal``, terminal feedback of radius 2 and an action map of power 2 after it."""
    def make(folder, task: str, terminal: bool = False):
        import numpy as np
        import torch

        from satenv import tasks
        from satenv.training.actor import MLPActor
        from satenv.training.envs import policy_env_meta
        from satenv.training.policy import LearnedPolicy, ObsNormalizer, save_artifacts
        from satenv.training.shaping import ActionMap, ObsFeatures, TerminalFeedback

        env = tasks.get(task).make_env()
        agent = env.possible_agents[0]
        obs_dim, act_dim = env.observation_space(agent).shape[0], env.action_space(agent).shape[0]
        torch.manual_seed(0)
        actor = MLPActor(obs_dim + 6, act_dim, [16, 16], "relu", squash=True)
        rng = np.random.default_rng(0)
        norm = ObsNormalizer(rng.normal(0.0, 0.1, obs_dim + 6), rng.uniform(0.5, 2.0, obs_dim + 6), 10.0)
        config = {"obs_symlog_scale": 10.0, "obs_symlog_dims": 6,
                  **({"terminal": {"radius": 2.0}, "action_power": 2.0} if terminal else {})}
        policy = LearnedPolicy(actor, norm, obs_shape=(obs_dim,), features=ObsFeatures(10.0, 6),
                               action_map=ActionMap(2.0) if terminal else None,
                               terminal=TerminalFeedback(radius=2.0) if terminal else None)
        meta = policy_env_meta(tasks.get(task).env_id, env, {}, {})
        return save_artifacts(folder, policy, env_meta=meta, config=config)
    return make
