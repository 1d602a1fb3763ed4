"""The ``guard`` section: the finiteness guard's cost in the PettingZoo step and the
``make_vec`` step."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from ._common import AGENTS, PettingZooLoop, _best_call_s, _rate

GUARD_TARGET = 0.05
"""The guard must cost under 5 % of the PettingZoo step time."""


def _fused_check_s(core, number: int = 2000) -> float:
    """Seconds the compiled kernel's fused finiteness check adds to its pass: the best time of
    the kernel with the check on minus off, interleaved three times (0 if not measurable)."""
    accel = np.zeros(core.x.shape[:-1] + (3,))
    timed: dict[bool, list[float]] = {True: [], False: []}
    for _ in range(3):
        for flag in (True, False):
            core.fused_check = flag
            timed[flag].append(_best_call_s(lambda: core._evaluate_kernel(core.x, accel, observe=True),
                                            number=number))
    core.fused_check = True
    return max(min(timed[True]) - min(timed[False]), 0.0)


def guard_cost(min_time: float = 0.5, batches: list[int] = (1, 64, 1024),
               log: Callable[[str], None] = print) -> dict:
    """The finiteness guard's cost (``satenv.dynamics._checks``): the check alone on one step's
    arrays (best of repeats, so the machine's load barely matters) as a share of the step time,
    for the ``platoon_v0`` PettingZoo step (also an A/B: the median of paired ratios of blocks of
    steps with the check on and off, interleaved) and the ``make_vec`` step of each batch size.
    With the compiled platoon kernel the check is fused into its pass
    (``PlatoonCore.fused_check``): its cost is the kernel's time with it on minus off, plus the
    env's read of the flag."""
    import satenv
    from satenv.dynamics._checks import all_finite

    env = satenv.make("platoon_v0")
    core = env.core
    loop, guard, fused = PettingZooLoop(env, -1.0, 1.0), env._finite_step, core.fused_check

    def enable(on: bool) -> None:   # the kernel's fused check, else the env's StepGuard
        env._finite_step = guard if on else (lambda *args: True)
        if fused:
            core.fused_check = on

    on, off, start = [], [], time.perf_counter()
    while time.perf_counter() - start < 4 * min_time or len(on) < 10:
        for enabled in ((True, False) if len(on) % 2 else (False, True)):
            enable(enabled)
            t0 = time.perf_counter()
            n = loop._chunk()
            (on if enabled else off).append((time.perf_counter() - t0) / n * AGENTS)
    enable(True)
    env.reset(seed=0)
    res, obs = core.step(np.zeros((1, AGENTS, 3))), core.observe()
    if fused:
        check = _fused_check_s(core) + _best_call_s(lambda: res.finite[0])
    else:
        check = _best_call_s(lambda: guard(obs, res.info["state"], sum(res.rewards[0].tolist())))
    step = float(np.median(off))
    pz = {"step_us": 1e6 * step, "step_us_fastest": 1e6 * min(off), "check_us": 1e6 * check,
          "check": "fused in the compiled kernel" if fused else "StepGuard",
          "check_share": check / step, "check_share_of_fastest": check / min(off),
          "ab_overhead": float(np.median(np.array(on) / np.array(off)) - 1), "ab_pairs": len(on)}
    rows = []
    for batch in batches:
        vec = satenv.make_vec("platoon_v0", batch, seed=0)
        vec.reset()
        acts = np.random.default_rng(0).uniform(-1.0, 1.0, vec.action_shape)
        rate = _rate(lambda vec=vec, acts=acts: vec.step(acts), batch * AGENTS, min_time / 2)
        o, r, _, _, info = vec.step(acts)
        if vec.core.fused_check:
            ok = np.ones(batch, bool)
            check_b = _fused_check_s(vec.core, number=200) + _best_call_s(ok.all, number=200)
        else:
            check_b = _best_call_s(lambda o=o, s=info["state"], r=r: all_finite(o, s, r), number=200)
        step_b = batch * AGENTS / rate
        rows.append({"batch": batch, "step_us": 1e6 * step_b, "check_us": 1e6 * check_b,
                     "check_share": check_b / step_b})
        log(f"guard make_vec batch {batch:>5}: check {1e6 * check_b:.2f} us = "
            f"{100 * rows[-1]['check_share']:.2f} % of the {1e6 * step_b:.0f} us step")
    log(f"guard PettingZoo: check {pz['check_us']:.2f} us = {100 * pz['check_share']:.2f} % of the median "
        f"{pz['step_us']:.0f} us step ({100 * pz['check_share_of_fastest']:.2f} % of the fastest); "
        f"A/B {100 * pz['ab_overhead']:+.2f} % over {pz['ab_pairs']} pairs")
    return {"pettingzoo": pz, "make_vec": rows, "target_share": GUARD_TARGET,
            "met": bool(pz["check_share_of_fastest"] < GUARD_TARGET)}
