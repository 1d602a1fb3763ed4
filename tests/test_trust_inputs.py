"""Replayed configs are data, and the remaining entry points' caps and types (issue 29 items 2, 4).

``satenv.training.trust.check_replayed_config`` admits only registered env ids and baseline names (a
``module:callable`` env id only with ``allow_code_env_id=True``) and imports nothing it names;
``satenv train --config`` calls it before anything runs. Then: ``make_vec(...).reset(
indices=...)``, ``satenv.make`` with a non-string id, ``scoreboard --out`` naming a file,
overflowing scenario fields, ``cluster_v0(n_neighbours=10**400)`` and a TorchRL ``device`` this
torch lacks — each a clear error naming the field.
"""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import satenv
from satenv.baselines.registry import BASELINES
from satenv.errors import SatenvError, SatenvTypeError
from satenv.training.trust import CODE_FLAG, UntrustedDataError, check_replayed_config

FAST = settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))
SHIPPED_CONFIG = "satenv/training/policies/platoon_tplf_ppo/config.json"


# ------------------------------------------------------------------- replayed configs
def test_registered_ids_and_baselines_pass():
    for env_id in satenv.ENV_IDS:
        check_replayed_config({"env_id": env_id, "eval_baselines": ["auto", *BASELINES]})
    check_replayed_config({"env_id": "platoon_v0", "expert": "dmpc"})
    check_replayed_config(json.loads(open(SHIPPED_CONFIG).read()))


_NAMES = st.one_of(st.text(max_size=20), st.sampled_from(["subprocess:run", "os:system", "builtins:exec",
                                                          "json.tool:main", "platoon_v0 ", "PLATOON_V0"]))


@FAST
@given(env_id=st.one_of(_NAMES, st.integers(), st.none(), st.lists(st.text(max_size=3), max_size=2)),
       allow=st.booleans())
def test_only_registered_env_ids_pass_and_nothing_is_imported(env_id, allow):
    before = set(sys.modules)
    data = {"env_id": env_id}
    if isinstance(env_id, str) and (env_id in satenv.ENV_IDS or (allow and ":" in env_id)):
        check_replayed_config(data, allow_code_env_id=allow)
    else:
        with pytest.raises(UntrustedDataError, match="env_id"):
            check_replayed_config(data, allow_code_env_id=allow)
    assert set(sys.modules) - before <= {"satenv.baselines.registry"}, set(sys.modules) - before


@FAST
@given(names=st.lists(st.one_of(_NAMES, st.integers(), st.none()), max_size=3), key=st.sampled_from(
    ["eval_baselines", "expert"]))
def test_only_registered_baselines_pass(names, key):
    data = {"env_id": "platoon_v0", key: names if key == "eval_baselines" else (names[0] if names else "x")}
    listed = data[key] if key == "eval_baselines" else [data[key]]
    if all(isinstance(n, str) and (n in BASELINES or n == "auto") for n in listed):
        check_replayed_config(data)
    else:
        with pytest.raises(UntrustedDataError, match="baseline|eval_baselines"):
            check_replayed_config(data)


def test_the_code_flag_must_be_a_bool_and_the_config_an_object():
    with pytest.raises(UntrustedDataError, match="allow_code_env_id"):
        check_replayed_config({}, allow_code_env_id="yes")
    for bad in ([], "platoon_v0", None):
        with pytest.raises(UntrustedDataError, match="JSON object"):
            check_replayed_config(bad)


def _refusal(main, argv, capsys) -> str:
    """The message of a command line refused before it runs: a ``SystemExit`` with the message, or a
    status 2 (returned or exited with) and its stderr."""
    try:
        status = main(argv)
    except SystemExit as stop:
        if not isinstance(stop.code, int):
            return str(stop)
        status = stop.code
    assert status == 2, f"accepted: {argv}"
    return capsys.readouterr().err


@pytest.mark.parametrize("cli", ["train", "imitation.cli", "benchmarl_train", "rllib_train"])
def test_config_replay_refuses_code_before_anything_runs(tmp_path, cli, capsys):
    """The audit's case: ``env_id: "subprocess:run"`` ran a shell command before the type check.
    Every CLI reads ``--config`` through ``satenv.training.config.load_config``, which vets it."""
    import importlib
    import re

    main = importlib.import_module(f"satenv.training.{cli}").main

    marker = tmp_path / "PWNED"
    cfg = json.loads(open(SHIPPED_CONFIG).read())
    cfg.update(env_id="subprocess:run", env_kwargs={"args": f"touch {marker}", "shell": True},
               out_dir=str(tmp_path / "run"))
    (tmp_path / "config.json").write_text(json.dumps(cfg))
    refusal = _refusal(main, ["--config", str(tmp_path / "config.json")], capsys)
    assert re.search(f"module:callable.*{CODE_FLAG}", refusal)
    cfg.update(env_id="platoon_v0", env_kwargs={}, eval_baselines=["os:system"])
    (tmp_path / "config.json").write_text(json.dumps(cfg))
    assert "baseline 'os:system' is not registered" in _refusal(main, ["--config", str(tmp_path / "config.json")],
                                                                capsys)
    assert not marker.exists() and not (tmp_path / "run").exists()


# ------------------------------------------------------------------- caps and types
@FAST
@given(indices=st.one_of(
    st.lists(st.floats(allow_nan=True), min_size=1, max_size=3),
    st.lists(st.text(max_size=2), min_size=1, max_size=2),
    st.lists(st.integers(-5, 10), max_size=4),
    st.lists(st.booleans(), min_size=1, max_size=5),
    st.sampled_from([0.5, "x", None, object(), [[0, 1], [2]], [1 + 1j]])))
def test_vec_reset_indices_are_ints_or_a_mask(indices):
    vec = satenv.make_vec("platoon_v0", 3, seed=0)
    vec.reset()
    try:
        obs, _ = vec.reset(indices=indices)
    except SatenvError as exc:
        assert "indices" in str(exc)
    else:
        idx = np.asarray(indices)
        assert idx.size == 0 or idx.dtype.kind in "biu" or indices is None
        assert np.isfinite(obs).all()
    vec.step(np.zeros(vec.action_shape))  # still usable


@pytest.mark.parametrize("env_id", [["platoon_v0"], None, 3, {"a": 1}, b"platoon_v0"])
def test_make_with_a_non_string_id_names_it(env_id):
    with pytest.raises(SatenvTypeError, match="unknown env id"):
        satenv.make(env_id)
    with pytest.raises(SatenvError, match="unknown env id"):
        satenv.make("platoon_v9")


@pytest.mark.parametrize(("env_id", "field", "value"), [
    ("platoon_v0", "desired_error", [0, -8e300, 0, 0, 0, 0]),
    ("platoon_v0", "u_max", 1e300),
    ("platoon_v0", "reward_scale", 1e200),
    ("cluster_v0", "n_neighbours", 10**400),
    ("cluster_v0", "comm_range", 1e308),
])
def test_huge_scenario_fields_are_rejected_by_their_own_name(env_id, field, value):
    with pytest.raises(SatenvError, match=field):
        satenv.make(env_id, **{field: value})


def test_scoreboard_out_naming_a_file_is_the_cli_error(tmp_path, capsys):
    from satenv.bench.scoreboard.cli import main

    target = tmp_path / "passwd"
    target.write_text("root:x:0:0\n")
    assert "exists and is not a folder" in _refusal(main, ["--out", str(target), "--quick", "--no-progress",
                                                           "--no-plots"], capsys)
    assert target.read_text() == "root:x:0:0\n"


def test_torchrl_device_this_torch_lacks_names_device():
    pytest.importorskip("torchrl")
    import torch

    from satenv.torchrl import make_env

    bad = ["gpu", None, 3.5] + ([] if torch.cuda.is_available() else ["cuda:7"])
    for device in bad:
        with pytest.raises(SatenvError, match="device must be a torch device"):
            make_env("platoon_v0", 2, device=device)
