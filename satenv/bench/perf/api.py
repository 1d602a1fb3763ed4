"""The ``api`` and ``mpe2`` sections: the PettingZoo dict API of ``platoon_v0`` beside mpe2
``simple_spread``, timed in interleaved repeats."""

from __future__ import annotations

import math

from ._common import PettingZooLoop


def api_loops(min_time: float, repeats: int = 3) -> tuple[dict, dict]:
    """(a) platoon_v0 (cw and j2) and (c) mpe2 simple_spread, timed in interleaved repeats so that
    a machine shared with other jobs affects both alike."""
    loops: dict[str, PettingZooLoop] = {}
    notes: dict[str, dict] = {}
    import satenv

    loops["api"] = PettingZooLoop(satenv.make("platoon_v0"), -1.0, 1.0)
    loops["api_j2"] = PettingZooLoop(satenv.make("platoon_v0", dynamics="j2",
                                                 inclination=math.radians(51.6)), -1.0, 1.0)
    try:
        from mpe2 import simple_spread_v3
    except ModuleNotFoundError as exc:
        notes["mpe2"] = {"skipped": f"mpe2 not installed ({exc}); pip install 'satenv[peers]'"}
    else:
        loops["mpe2"] = PettingZooLoop(simple_spread_v3.parallel_env(continuous_actions=True, max_cycles=180),
                                       0.0, 1.0)
    for _ in range(repeats):
        for loop in loops.values():
            loop.measure(min_time)
    api = notes.get("api") or {"env": "platoon_v0 (pereira2023, PLF, cw, 4 followers)", **loops["api"].result(),
                               "j2_agent_steps_per_s": loops["api_j2"].best}
    mpe = notes.get("mpe2") or {"env": "mpe2 simple_spread_v3 (3 agents, continuous, max_cycles=180)",
                                **loops["mpe2"].result()}
    return api, mpe
