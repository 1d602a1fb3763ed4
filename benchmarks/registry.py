"""What the scoreboard runs: named scenarios (env factories) and named policies (factories of env).

Every entry points at its code by ``"module:attribute"`` strings, tried in order, so an entry whose
module has not landed yet (or whose optional dependency is not installed) is *skipped with a note*
instead of breaking the board. Only the absence of that specific module is tolerated: any other
import error inside an existing module is a bug and propagates.

Adding an env or a baseline is one entry here::

    SCENARIOS["cluster-case1"] = ScenarioSpec("cluster-case1", ("satenv.envs.cluster_v0:parallel_env",),
                                              {"preset": "li2022-case1"})
    POLICIES["apf"] = PolicySpec("apf", ("baselines:APF",), baseline="apf")  # where: APF.supports(env)

A scenario spec builds a PettingZoo ``ParallelEnv`` with ``factory(**kwargs)``; a policy spec
builds a policy with ``factory(env, **kwargs)`` (or, for a checkpoint, ``training.load(path)``).
A scripted policy applies where its ``baselines`` class's ``supports(env)`` says; a trained one
where the ``fnmatch`` patterns ``scenarios`` over scenario names say.
"""

from __future__ import annotations

import fnmatch
import hashlib
import importlib
import importlib.util
import inspect
import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = [
    "FULL", "POLICIES", "QUICK", "SCENARIOS", "PolicySpec", "ScenarioSpec", "ScoreboardError",
    "checkpoint_policy", "discover_trained_policies", "resolve",
]

SHIPPED_POLICY_DIR = Path(__file__).resolve().parent.parent / "training" / "policies"


class ScoreboardError(ValueError):
    """Bad scoreboard input (unknown name, unreadable checkpoint, incompatible policy, ...)."""


class Unavailable(Exception):
    """An entry whose code (or optional dependency) is not importable here; ``str`` says why."""


def _module_missing(exc: ModuleNotFoundError, module: str) -> bool:
    """True when ``exc`` is about ``module`` itself (or one of its parent packages) being absent."""
    name = exc.name or ""
    return bool(name) and (module == name or module.startswith(name + "."))


def resolve(targets: tuple[str, ...], requires: tuple[str, ...] = ()) -> Callable[..., Any]:
    """The first importable ``"module:attribute"`` of ``targets``; :class:`Unavailable` if none.

    ``requires`` lists optional third-party modules; a missing one makes the entry unavailable.
    """
    for dep in requires:
        if importlib.util.find_spec(dep) is None:
            raise Unavailable(f"optional dependency {dep!r} is not installed")
    reasons = []
    for target in targets:
        module, _, attr = target.partition(":")
        try:
            mod = importlib.import_module(module)
        except ModuleNotFoundError as exc:
            if not _module_missing(exc, module):
                raise
            reasons.append(f"module {module} not found")
            continue
        try:
            obj = getattr(mod, attr, None)
        except ModuleNotFoundError as exc:  # a lazy attribute whose submodule has not landed
            if not (exc.name or "").startswith(module + "."):
                raise
            reasons.append(f"module {exc.name} not found")
            continue
        if obj is None:
            reasons.append(f"{module} has no {attr}")
            continue
        return obj
    raise Unavailable("; ".join(dict.fromkeys(reasons)) or "no target given")


def _fingerprint(payload: Mapping[str, Any]) -> str:
    """Short stable hash of a JSON-able description (records which definition made an episode)."""
    text = json.dumps(payload, sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


@dataclass(frozen=True)
class ScenarioSpec:
    """A named env configuration: ``factory(**kwargs)`` for the first importable ``targets``.

    Args:
        name: scoreboard name, e.g. ``"platoon-PLF-cw"``.
        targets: ``"module:attribute"`` candidates of the env factory.
        kwargs: keyword arguments of the factory.
        description: one line for the scoreboard header.
        success_tol: position tolerance [m] of ``satenv.metrics.summary``'s success / convergence.
        collision_free_success: success also requires zero collisions (``metrics.success``); set
            ``False`` where the scenario's own target formation puts bodies closer than their
            collision distance (then success = every agent within ``success_tol`` at the end, and
            collisions are still counted and shown).
        requires: optional third-party modules the env needs.
    """

    name: str
    targets: tuple[str, ...]
    kwargs: Mapping[str, Any] = field(default_factory=dict)
    description: str = ""
    success_tol: float = 1.0
    collision_free_success: bool = True
    requires: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ScoreboardError(f"scenario name must be a non-empty string, got {self.name!r}")
        if isinstance(self.targets, str) or not self.targets:
            raise ScoreboardError(f"scenario {self.name}: targets must be a tuple of 'module:attr', "
                                  f"got {self.targets!r}")
        if not self.success_tol > 0:
            raise ScoreboardError(f"scenario {self.name}: success_tol must be > 0, got {self.success_tol!r}")

    def factory(self) -> Callable[..., Any]:
        return resolve(self.targets, self.requires)

    def make(self):
        """A fresh env (raises :class:`Unavailable` if the env's module has not landed)."""
        return self.factory()(**dict(self.kwargs))

    def fingerprint(self) -> str:
        return _fingerprint({"targets": self.targets, "kwargs": dict(self.kwargs),
                             "success_tol": self.success_tol,
                             "collision_free_success": self.collision_free_success})


@dataclass(frozen=True)
class PolicySpec:
    """A named policy: ``factory(env, **kwargs)``, or ``training.load(checkpoint)``.

    Args:
        name: scoreboard name, e.g. ``"dmpc"``.
        targets: ``"module:attribute"`` candidates of the policy class / factory.
        kwargs: keyword arguments after ``env``.
        scenarios: ``fnmatch`` patterns of the scenario names the policy applies to.
        description: one line for the scoreboard header.
        checkpoint: path of a trained policy (then ``targets`` is the loader, ``training:load``).
        requires: optional third-party modules (e.g. the QP solver).
        dry_run: act once on a reset env before the run to check compatibility (cheap policies).
        learned: a trained network (its observation space is checked against the env's).
        baseline: the ``baselines.BASELINES`` name of a scripted policy; then its class's
            ``supports(env)`` says where it applies (``scenarios`` is not used).
    """

    name: str
    targets: tuple[str, ...]
    kwargs: Mapping[str, Any] = field(default_factory=dict)
    scenarios: tuple[str, ...] = ("*",)
    description: str = ""
    checkpoint: str | None = None
    requires: tuple[str, ...] = ()
    dry_run: bool = True
    learned: bool = False
    baseline: str | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ScoreboardError(f"policy name must be a non-empty string, got {self.name!r}")
        if isinstance(self.targets, str) or not self.targets:
            raise ScoreboardError(f"policy {self.name}: targets must be a tuple of 'module:attr', "
                                  f"got {self.targets!r}")
        if isinstance(self.scenarios, str):
            raise ScoreboardError(f"policy {self.name}: scenarios must be a tuple of patterns, "
                                  f"got the string {self.scenarios!r}")

    def applies_to(self, scenario: str, env: Any = None) -> bool:
        """Whether the policy runs on ``scenario`` (its env ``env``, asked of the baseline class)."""
        if self.baseline is not None:
            import baselines

            return env is not None and baselines.get(self.baseline).supports(env)
        return any(fnmatch.fnmatchcase(scenario, pat) for pat in self.scenarios)

    def where(self) -> str:
        """Where the policy applies, for listings."""
        if self.baseline is not None:
            import baselines

            return baselines.get(self.baseline).supported()
        return "scenarios " + ",".join(self.scenarios)

    def factory(self) -> Callable[..., Any]:
        return resolve(self.targets, self.requires)

    def make(self, env):
        """A fresh policy for ``env``."""
        fn = self.factory()
        if self.checkpoint is not None:
            return checkpoint_policy(fn, self.checkpoint, env)
        return fn(env, **dict(self.kwargs))

    def fingerprint(self) -> str:
        payload: dict[str, Any] = {"targets": self.targets, "kwargs": dict(self.kwargs)}
        if self.checkpoint is not None:
            payload["checkpoint"] = _content_hash(Path(self.checkpoint))
        return _fingerprint(payload)


def _content_hash(path: Path) -> str:
    """Hash of a checkpoint file, or of every file under a checkpoint directory."""
    h = hashlib.sha256()
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    for p in files:
        h.update(str(p.relative_to(path) if path.is_dir() else p.name).encode())
        try:
            h.update(p.read_bytes())
        except OSError:
            h.update(b"<unreadable>")
    return h.hexdigest()[:16]


def checkpoint_policy(load: Callable[..., Any], path: str, env) -> Any:
    """``load(path)`` (passing ``env=env`` when the loader accepts it) as a policy for ``env``."""
    try:
        params = inspect.signature(load).parameters
    except (TypeError, ValueError):
        params = {}
    policy = load(path, env=env) if "env" in params else load(path)
    for method in ("reset", "act"):
        if not callable(getattr(policy, method, None)):
            raise ScoreboardError(f"training.load({path!r}) returned {type(policy).__name__}, which has "
                                  f"no {method}() method; expected a policy with reset(seed) and "
                                  f"act(observations)")
    if not hasattr(policy, "info"):
        try:
            policy.info = {}
        except AttributeError:
            pass
    return policy


# ----------------------------------------------------------------------------------------------
# The registry.
# ----------------------------------------------------------------------------------------------
_PLATOON = ("satenv.envs.platoon_v0:parallel_env",)
_CLUSTER = ("satenv.envs.cluster_v0:parallel_env",)
_SERVICING = ("satenv.envs.servicing_v0:parallel_env",)
_FORMATION = ("satenv.envs.formation_v0:parallel_env",)


_ISS_INCLINATION = math.radians(51.6)
_TABLE1_NOTE = ("the Table I formation puts followers closer than 2 r_f, so collisions are counted "
                "but do not end the episode or void success")


def _platoon(name: str, description: str, collision_free_success: bool = False, **kwargs) -> ScenarioSpec:
    """A platoon_v0 scenario; pereira2023-based ones run without collision termination (as the
    paper's reproduction): its target formation itself is closer than 2 r_f."""
    return ScenarioSpec(name, _PLATOON, kwargs, description,
                        collision_free_success=collision_free_success)


SCENARIOS: dict[str, ScenarioSpec] = {s.name: s for s in [
    *[_platoon(f"platoon-{topo}-{dyn}",
               f"pereira2023 Table I, {topo} topology, {dyn} truth"
               + (" (chief inclination 51.6 deg)" if dyn == "j2" else "") + f"; {_TABLE1_NOTE}",
               preset="pereira2023", topology=topo, dynamics=dyn, terminate_on_collision=False,
               **({"inclination": _ISS_INCLINATION} if dyn == "j2" else {}))
      for dyn in ("cw", "j2") for topo in ("PLF", "BDL", "TPLF")],
    _platoon("platoon-random-cw", f"pereira2023 PLF with randomised initial states, cw; {_TABLE1_NOTE}",
             preset="pereira2023", randomize=True, terminate_on_collision=False),
    _platoon("platoon-random-j2", f"pereira2023 PLF with randomised initial states, j2 (51.6 deg); "
             f"{_TABLE1_NOTE}", preset="pereira2023", randomize=True, dynamics="j2",
             inclination=_ISS_INCLINATION, terminate_on_collision=False),
    _platoon("platoon-chain-cw", "pereira2023 Table I start, PLF, chain formation (followers 8 m apart, "
             "collision-free target); a collision ends the episode", collision_free_success=True,
             preset="pereira2023", formation="chain", terminate_on_collision=True),
    _platoon("platoon-tplf30-random-cw", "pereira2023 TPLF with E_d = [0, -30, 0] (targets 8-15 m apart) "
             "and randomised initial states, cw; a collision ends the episode (the shipped "
             "policy's scenario)", collision_free_success=True, preset="pereira2023",
             topology="TPLF", desired_error=(0.0, -30.0, 0.0, 0.0, 0.0, 0.0), randomize=True,
             terminate_on_collision=True),
    _platoon("platoon-pereira2022", "pereira2022 §5.1: 2 followers in a chain, keep-out sphere, LOS cone "
             "(collision-free success)", collision_free_success=True, preset="pereira2022"),
    ScenarioSpec("cluster-case1", _CLUSTER, {"preset": "li2022-case1"},
                 "li2022 case 1: 10 satellites, moving obstacle, J2 + drag + disturbance"),
    ScenarioSpec("cluster-case2", _CLUSTER, {"preset": "li2022-case2"},
                 "li2022 case 2: 10 satellites, moving obstacle, J2 + drag + disturbance"),
    ScenarioSpec("servicing-pereira2022", _SERVICING, {"preset": "pereira2022"},
                 "pereira2022 §5.2: 6-DOF servicing around a passive object", success_tol=0.5),
    ScenarioSpec("formation-kannan2022-position", _FORMATION, {"preset": "kannan2022-position"},
                 "kannan2022 §5.1: 3 spacecraft to a connected in-plane network"),
    ScenarioSpec("formation-kannan2022-collision", _FORMATION, {"preset": "kannan2022-collision"},
                 "kannan2022 §5.2: leader-follower y-spacing of 10 m"),
]}
"""Every scenario of the scoreboard by name (entries whose env has not landed are skipped)."""

POLICIES: dict[str, PolicySpec] = {p.name: p for p in [
    PolicySpec("zero", ("baselines.base:ZeroPolicy",), baseline="zero",
               description="no thrust (coasting)"),
    PolicySpec("random", ("baselines.base:RandomPolicy",), baseline="random",
               description="uniform random thrust"),
    PolicySpec("dmpc", ("baselines:DMPC",), baseline="dmpc",
               requires=("daqp",), description="1-hop distributed MPC (pereira2023/2022)"),
    PolicySpec("tube_rdmpc", ("baselines:TubeRDMPC",), baseline="tube_rdmpc",
               requires=("casadi",), dry_run=False, description="tube-based robust DMPC (li2022)"),
    PolicySpec("apf", ("baselines:APF",), baseline="apf",
               description="artificial potential field (li2022)"),
    PolicySpec("nmpc", ("baselines:NMPC",), baseline="nmpc",
               requires=("casadi",), dry_run=False, description="cooperative NMPC (pereira2022 §4)"),
    PolicySpec("cgmres", ("baselines:CGMRES",), baseline="cgmres",
               requires=("casadi",), dry_run=False, description="centralised C/GMRES NMPC (kannan2022)"),
]}
"""Every scripted policy by name; shipped trained policies are added by
:func:`discover_trained_policies`."""

QUICK: dict[str, Any] = {
    "scenarios": ["platoon-PLF-cw", "platoon-BDL-j2", "platoon-chain-cw", "platoon-tplf30-random-cw",
                  "platoon-pereira2022", "formation-kannan2022-position", "cluster-case1"],
    "policies": ["zero", "random", "dmpc", "apf", "cgmres", "trained:*"],
    "seeds": [0, 1, 2],
    "scenario_seeds": {"cluster-case1": [0]},   # ~10 s per episode: one seed in the quick board
}
"""The ``--quick`` board (the README's first command): a few minutes on 2 cores at most.
Names that are not available yet are skipped with a note."""

FULL: dict[str, Any] = {
    "seeds": "0-9",
    # the costliest pairs: tube-RDMPC ~0.6 s x 400 decisions per cluster episode, NMPC ~0.8 s x
    # 1200 decisions per servicing episode (measured on 2 shared cores)
    "scenario_seeds": {"cluster-case1": [0, 1, 2, 3, 4], "cluster-case2": [0, 1, 2, 3, 4],
                       "servicing-pereira2022": [0, 1, 2]},
}
"""The full (published) board: every available scenario x applicable policy x these seeds."""


def discover_trained_policies(root: Path = SHIPPED_POLICY_DIR) -> dict[str, PolicySpec]:
    """One ``trained:<name>`` entry per shipped artefact folder under ``training/policies/``.

    It applies to the scenarios of the env it was trained on (``env.json``'s ``env_id``, e.g.
    ``platoon_v0`` -> ``platoon-*``), or to the patterns of an optional ``scoreboard.json``
    (``{"scenarios": [patterns]}``); scenarios whose spaces it does not fit are skipped with a
    note before the run.
    """
    out: dict[str, PolicySpec] = {}
    if not root.is_dir():
        return out
    for path in sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith((".", "_"))):
        patterns: tuple[str, ...] = ("*",)
        try:
            env_id = json.loads((path / "env.json").read_text()).get("env_id", "")
            if isinstance(env_id, str) and env_id:
                patterns = (env_id.split("_v")[0] + "-*",)
        except (OSError, ValueError, AttributeError):
            pass
        meta = path / "scoreboard.json"
        if meta.is_file():
            try:
                patterns = tuple(json.loads(meta.read_text())["scenarios"])
            except (OSError, ValueError, KeyError, TypeError) as exc:
                raise ScoreboardError(f"{meta}: expected JSON {{\"scenarios\": [patterns]}}, got an "
                                      f"unreadable file ({exc})") from None
        name = f"trained:{path.name}"
        out[name] = PolicySpec(name, ("training:load",), scenarios=patterns, checkpoint=str(path),
                               learned=True, requires=("stable_baselines3",),
                               description=f"shipped trained policy {path.name}")
    return out
