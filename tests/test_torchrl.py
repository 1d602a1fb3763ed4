"""satenv.torchrl.make_env: the native TorchRL env over make_vec (needs the marl extra)."""

from importlib.util import find_spec

import numpy as np
import pytest

import satenv

pytestmark = pytest.mark.skipif(find_spec("torchrl") is None,
                                reason="torchrl not installed (pip install -c constraints.txt -e '.[marl]')")


@pytest.mark.parametrize("env_id", satenv.ENV_IDS)
def test_check_env_specs(env_id):
    from torchrl.envs.utils import check_env_specs

    from satenv.torchrl import make_env

    env = make_env(env_id, 2, seed=0, max_steps=2)
    check_env_specs(env)
    assert env.batch_size == (2,) and env.group_map == {"agents": env.vec.agents}


def test_copies_reproduce_the_pettingzoo_env_and_reset_through_torchrl():
    import torch

    from satenv.torchrl import make_env

    steps, seed, b = 3, 4, 3
    kw = {"max_steps": steps, "randomize": True}
    env = make_env("platoon_v0", b, seed=seed, **kw)
    pz = [satenv.make("platoon_v0", **kw) for _ in range(b)]
    agents = pz[0].possible_agents
    actions = torch.as_tensor(np.random.default_rng(0).uniform(-1, 1, (2 * steps, b, len(agents), 3)),
                              dtype=torch.float32)
    td = env.reset()
    obs = [p.reset(seed=seed + i)[0] for i, p in enumerate(pz)]
    for k in range(2 * steps):  # TorchRL resets the finished copies through "_reset"
        for i in range(b):
            np.testing.assert_array_equal(td["agents", "observation"][i].numpy(), np.stack([obs[i][a] for a in agents]))
            np.testing.assert_allclose(td["state"][i].numpy(), pz[i].state(), rtol=1e-6)
        td["agents", "action"] = actions[k]
        out, td = env.step_and_maybe_reset(td)
        for i, p in enumerate(pz):
            o, r, te, tr, _ = p.step({a: actions[k, i, j].double().numpy() for j, a in enumerate(agents)})
            np.testing.assert_allclose(out["next", "agents", "reward"][i, :, 0].numpy(), [r[a] for a in agents],
                                       rtol=1e-6)
            assert bool(out["next", "done"][i]) == (te[agents[0]] or tr[agents[0]]) == ((k + 1) % steps == 0)
            obs[i] = p.reset()[0] if (te[agents[0]] or tr[agents[0]]) else o


def test_vector_without_autoreset_needs_an_explicit_reset():
    from satenv.envs.base import SatenvError
    from satenv.vector import SatVectorEnv

    vec = SatVectorEnv(satenv.make("platoon_v0", max_steps=1), 3, seed=0, autoreset=False)
    vec.reset()
    *_, infos = vec.step(np.zeros(vec.action_shape))
    assert "_final" not in infos
    with pytest.raises(SatenvError, match="have ended"):
        vec.step(np.zeros(vec.action_shape))
    vec.reset(indices=np.array([True, True, False]))
    with pytest.raises(SatenvError, match=r"copies \[2\]"):
        vec.step(np.zeros(vec.action_shape))
    vec.reset(indices=[2])
    vec.step(np.zeros(vec.action_shape))
