"""The ``vmas`` section: VMAS ``navigation`` on CPU, the batched peer."""

from __future__ import annotations

from ._common import AGENTS, _rate

VMAS_ENV = "vmas navigation (4 agents, continuous actions, cpu, 1 torch thread)"


def vmas_navigation(batch: int, min_time: float) -> dict:
    """Agent-steps/s of VMAS ``navigation`` (``env.step``) with ``batch`` vectorised envs on CPU;
    ``{"skipped": why}`` when VMAS is not installed."""
    try:
        import torch
        import vmas
    except ModuleNotFoundError as exc:
        return {"skipped": f"{exc.name} not installed; pip install vmas"}
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        env = vmas.make_env("navigation", num_envs=batch, device="cpu", continuous_actions=True,
                            n_agents=AGENTS, seed=0)
        env.reset()
        gen = torch.Generator().manual_seed(0)
        actions = [torch.rand((batch, 2), generator=gen) * 2 - 1 for _ in env.agents]
        rate = _rate(lambda: env.step(actions), batch * AGENTS, min_time)
    finally:
        torch.set_num_threads(threads)
    return {"batch": batch, "agents": batch * AGENTS, "agent_steps_per_s": rate,
            "version": getattr(vmas, "__version__", "?")}
