"""A GCBF-style learned barrier for the cluster network alone (README.md of this folder).

Each round flies the network alone (no filter, not stopped at a collision) on training seeds, then
trains a decentralised barrier ``h(o)`` on each satellite's safety entries (obstacle, target
spacecraft, neighbour slots) jointly with the network:

    L_h     = relu(g + h(o_unsafe)) + relu(g - h(o_safe))
    L_deriv = relu(g_d - (h(o+(pi(o))) - (1 - alpha) h(o)))        (the discrete barrier condition)
    L_pi    = |pi(o) - pi_0(o)|^2 + w_deriv L_deriv                    (pi_0: the shipped network)

``o+(a) = o+_flown + J (u(a) - u_flown)`` (:func:`satenv.envs.cluster_v0.own_action_jacobian`, the
nominal CW input matrix of :func:`satenv.safety.model.safety_model`): the next observation as a
differentiable function of the satellite's own action, its neighbours as flown. Both labels are
derived from the thrust bound (radial braking of a double integrator), not tuned:

* unsafe: inside a keep-out distance now, or doomed: closer to it than full thrust ``u_max`` can
  stop the closing speed in (``--no-doomed`` drops the second part);
* safe: beyond every keep-out distance by the braking distance at the filter's braking authority
  (``SafetyModel.brake``, the smaller) plus ``SAFE_MARGIN_M``.

After each round the network alone is evaluated on the validation seeds (``history.json``).

    nice -n 5 env OMP_NUM_THREADS=1 .venv/bin/python studies/runs/cluster_learned_barrier/train.py \\
        --out runs/cluster_learned_barrier
"""

from __future__ import annotations

import argparse
import copy
import json
import time
from pathlib import Path

import numpy as np
import torch

from satenv import tasks
from satenv.envs.cluster_v0 import N_FIXED_OBS, POS_SCALE, VEL_SCALE, own_action_jacobian
from satenv.safety.model import safety_model
from satenv.training.evaluate import evaluate
from satenv.training.imitation.barrier import env_action, terminal_affine
from satenv.training.policy import load

FOLDER = "satenv/training/policies/cluster_li2022_dagger_shield"
TASK = "cluster-case1-random"
TRAIN_SEED0 = 640_000            # inside the train band (tasks.SEED_SPLITS), unused by the earlier cluster runs
VAL_SEEDS = range(700_000, 700_020)
SAFE_MARGIN_M = 50.0
"""Extra distance [m] beyond the keep-out plus the braking distance for a state labelled safe."""
GAMMA_H, GAMMA_DERIV, ALPHA = 0.05, 0.01, 0.1
"""Margins of the barrier's sign conditions and of its discrete condition; its decay rate per decision."""


def safety_entries(o: torch.Tensor) -> tuple[torch.Tensor, list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]]]:
    """The barrier's input (the safety entries of the observation, plus each body's distance and
    closing speed) and per body ``(distance [m], closing speed [m/s], filled)``."""
    k = (o.shape[-1] - N_FIXED_OBS) // 7
    bodies = [(o[..., 9:12], o[..., 12:15], torch.ones_like(o[..., 0])),        # obstacle
              (o[..., 15:18], -o[..., 3:6], torch.ones_like(o[..., 0]))]        # target spacecraft (at rest)
    for j in range(k):
        s = o[..., N_FIXED_OBS + 7 * j:N_FIXED_OBS + 7 * (j + 1)]
        bodies.append((s[..., 1:4], s[..., 4:7], s[..., 0]))
    geo = []
    for r, v, filled in bodies:
        d = torch.linalg.norm(r * POS_SCALE, dim=-1).clamp_min(1e-6)
        closing = -(r * POS_SCALE * v * VEL_SCALE).sum(-1) / d
        geo.append((d, closing, filled))
    extra = torch.stack([t for d, c, f in geo for t in (f * d / POS_SCALE, f * c)], dim=-1)
    return torch.cat([o[..., 9:18], o[..., N_FIXED_OBS:], extra], dim=-1), geo


def labels(o: torch.Tensor, radii: list[float], brake: float, full_thrust: float,
           doomed: bool = True) -> tuple[torch.Tensor, torch.Tensor]:
    """``unsafe`` and ``safe`` masks of observations ``o``. Unsafe: inside a keep-out distance, or
    (``doomed``) closer to it than the distance full thrust ``full_thrust`` [m/s^2] needs to stop the
    closing speed. Safe: every body beyond keep-out + the braking distance at the filter's authority
    ``brake`` + ``SAFE_MARGIN_M``."""
    _, geo = safety_entries(o)
    unsafe = torch.zeros(o.shape[:-1], dtype=torch.bool)
    safe = torch.ones(o.shape[:-1], dtype=torch.bool)
    for (d, c, f), radius in zip(geo, radii, strict=True):
        on = f > 0.5
        closing2 = c.clamp_min(0.0) ** 2
        unsafe |= on & ((d < radius) | (doomed & (d - radius < closing2 / (2.0 * full_thrust))))
        stop = closing2 / (2.0 * brake)
        safe &= ~on | (d > radius + stop + SAFE_MARGIN_M)
    return unsafe, safe & ~unsafe


class Barrier(torch.nn.Module):
    def __init__(self, n_in: int, width: int = 128) -> None:
        super().__init__()
        self.net = torch.nn.Sequential(torch.nn.Linear(n_in, width), torch.nn.Tanh(),
                                       torch.nn.Linear(width, width), torch.nn.Tanh(), torch.nn.Linear(width, 1))

    def forward(self, o: torch.Tensor) -> torch.Tensor:
        return self.net(safety_entries(o)[0]).squeeze(-1)


def fly_alone(policy, env, seeds) -> dict[str, np.ndarray]:
    """Rows ``obs, act (flown), next`` of the network alone, episodes not stopped at a collision."""
    out = {"obs": [], "act": [], "next": []}
    for seed in seeds:
        obs, _ = env.reset(seed=int(seed))
        agents = list(env.agents)
        o = np.stack([obs[a] for a in agents]).astype(np.float64)
        while env.agents:
            a = policy.predict(o).astype(np.float64)
            nxt = env.step({ag: a[i] for i, ag in enumerate(agents)})[0]
            if not nxt:
                break
            o2 = np.stack([nxt[ag] for ag in agents]).astype(np.float64)
            for key, v in (("obs", o), ("act", a), ("next", o2)):
                out[key].append(v)
            o = o2
    return {k: np.concatenate(v) for k, v in out.items()}


def ball(a: torch.Tensor) -> torch.Tensor:
    return a / torch.linalg.norm(a, dim=-1, keepdim=True).clamp_min(1.0)


def train_round(policy, anchor, barrier, data, model, radii, args, gen) -> dict[str, float]:
    """The round's fit: Adam steps on minibatches drawn from every row so far, the barrier alone
    (``--h-steps``), then barrier and network (``--steps``)."""
    o = torch.as_tensor(data["obs"], dtype=torch.float32)
    nxt = torch.as_tensor(data["next"], dtype=torch.float32)
    x = torch.as_tensor(policy.network_input(data["obs"]), dtype=torch.float32)
    with torch.no_grad():
        y0 = anchor(x)
    s = torch.as_tensor(model.S, dtype=torch.float32)
    jac = torch.as_tensor(own_action_jacobian(data["obs"], model.B), dtype=torch.float32) @ s   # per unit action
    a_flown = ball(torch.as_tensor(data["act"], dtype=torch.float32))
    off, slope = (torch.as_tensor(v, dtype=torch.float32) for v in terminal_affine(policy, data["obs"], 3))
    power = float(policy.action_map.power) if policy.action_map is not None else 1.0
    unsafe, safe = labels(o, radii, model.brake, args.full_thrust, args.doomed)
    opt_h = torch.optim.Adam(barrier.parameters(), lr=args.lr_h)
    opt_pi = torch.optim.Adam(policy.actor.parameters(), lr=args.lr_pi)
    sums, count = np.zeros(5), 0
    for step in range(args.h_steps + args.steps):
        joint = step >= args.h_steps
        if step == args.h_steps:
            sums, count = np.zeros(5), 0          # the terms reported: those of the joint steps
        idx = torch.randint(len(o), (args.batch,), generator=gen)
        y = policy.actor(x[idx]) if joint else y0[idx]
        a = ball(off[idx] + slope[idx] * env_action(y, power))
        o_next = nxt[idx] + torch.einsum("nij,nj->ni", jac[idx], a - a_flown[idx])
        h, h_next = barrier(o[idx]), barrier(o_next)
        l_uns = (torch.relu(GAMMA_H + h) * unsafe[idx]).mean()
        l_safe = (torch.relu(GAMMA_H - h) * safe[idx]).mean()
        l_der = (torch.relu(GAMMA_DERIV - (h_next - (1 - ALPHA) * h)) * ~unsafe[idx]).mean()
        l_ctrl = ((y - y0[idx]) ** 2).sum(-1).mean() if joint else torch.zeros(())
        steps = [(list(barrier.parameters()), l_uns + l_safe + l_der, opt_h)]
        if joint:    # each its own terms: the barrier all three, the network the anchor and the condition
            steps.append((list(policy.actor.parameters()), l_ctrl + args.w_deriv * l_der, opt_pi))
        grads = [torch.autograd.grad(loss, params, retain_graph=True) for params, loss, _ in steps]
        for (params, _, opt), gs in zip(steps, grads, strict=True):
            for q, g in zip(params, gs, strict=True):
                q.grad = g
            opt.step()
        viol = ((h_next - (1 - ALPHA) * h) < 0) & ~unsafe[idx]
        sums += np.array([l_uns.item(), l_safe.item(), l_der.item(), l_ctrl.item(), viol.float().mean().item()])
        count += 1
    terms = dict(zip(("unsafe", "safe", "deriv", "ctrl", "deriv_violated_share"), (sums / count).tolist(),
                     strict=True))
    terms.update(rows=len(o), unsafe_rows=int(unsafe.sum()), safe_rows=int(safe.sum()))
    return terms


def validate(policy, seeds) -> dict[str, float]:
    env = tasks.get(TASK).make_env()
    agg = evaluate(env, policy, seeds, desc="validation (network alone)", progress=False)["aggregate"]
    return {k: agg.get(k) for k in ("episodes", "successes", "collision_episodes", "violation_episodes",
                                    "final_error_m", "steps")}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--episodes", type=int, default=12, help="alone flights per round")
    p.add_argument("--h-steps", type=int, default=1000, help="Adam steps of the barrier alone per round")
    p.add_argument("--steps", type=int, default=2000, help="Adam steps of barrier and network per round")
    p.add_argument("--batch", type=int, default=1024)
    p.add_argument("--lr-h", type=float, default=1e-3)
    p.add_argument("--lr-pi", type=float, default=1e-5)
    p.add_argument("--w-deriv", type=float, default=10.0)
    p.add_argument("--no-doomed", dest="doomed", action="store_false",
                   help="label unsafe only the states inside a keep-out distance (not those full thrust cannot stop)")
    p.add_argument("--first-seed", type=int, default=TRAIN_SEED0, help="the first flight's seed (train band)")
    p.add_argument("--init", type=Path, help="start network and barrier from a round file of an earlier run")
    args = p.parse_args()
    torch.manual_seed(0)
    gen = torch.Generator().manual_seed(0)
    args.out.mkdir(parents=True, exist_ok=True)
    policy = load(FOLDER, shielded=False)
    anchor = copy.deepcopy(policy.actor).eval()
    fly_env = tasks.get(TASK).make_env(terminate_on_collision=False)
    model = safety_model(fly_env)
    sc = fly_env.scenario
    k = (fly_env.observation_space(fly_env.possible_agents[0]).shape[0] - N_FIXED_OBS) // 7
    args.full_thrust = float(sc.u_max)
    radii = [sc.obstacle_distance, sc.target_distance] + [sc.pair_distance] * k
    barrier = Barrier(len(safety_entries(torch.zeros(1, N_FIXED_OBS + 7 * k))[0][0]))
    if args.init is not None:      # the anchor stays the shipped network
        start = torch.load(args.init, weights_only=True)
        policy.actor.load_state_dict(start["actor"])
        barrier.load_state_dict(start["barrier"])
    history = [{"round": -1, **validate(policy, VAL_SEEDS)}]
    print(json.dumps(history[-1]), flush=True)
    data: dict[str, np.ndarray] = {}
    for r in range(args.rounds):
        t0 = time.time()
        seeds = range(args.first_seed + r * args.episodes, args.first_seed + (r + 1) * args.episodes)
        new = fly_alone(policy, fly_env, seeds)
        data = {k_: np.concatenate([data[k_], v]) if data else v for k_, v in new.items()}
        t1 = time.time()
        terms = train_round(policy, anchor, barrier, data, model, radii, args, gen)
        t2 = time.time()
        row = {"round": r, **validate(policy, VAL_SEEDS), "fit": terms, "collect_s": round(t1 - t0, 1),
               "fit_s": round(t2 - t1, 1), "validate_s": round(time.time() - t2, 1)}
        history.append(row)
        print(json.dumps(row), flush=True)
        (args.out / "history.json").write_text(json.dumps({"args": {k_: str(v) for k_, v in vars(args).items()},
                                                           "history": history}, indent=1) + "\n")
        torch.save({"actor": policy.actor.state_dict(), "barrier": barrier.state_dict()}, args.out / f"round{r}.pt")


if __name__ == "__main__":
    main()
