"""Policy folders are untrusted data (issue 29 item 1): ``satenv.training.load`` and ``satenv.training.trust``.

Crafted folders: links out of (and inside) the folder, directories, FIFOs and sparse giant files
in place of members, safetensors headers declaring huge or wrong tensors, tampered bytes, a
missing manifest. Each must be refused with a :class:`satenv.training.PolicyLoadError` naming the file,
quickly, without reading outside the folder, without allocating past the cap and without
echoing the file's content; a good folder loads bit for bit.
"""

from __future__ import annotations

import json
import os
import struct
import time
import tracemalloc
import warnings

import numpy as np
import pytest
from audit_inputs import good_policy_folder
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from satenv import training
from satenv.training.policy import LEGACY_WEIGHTS, MANIFEST, POLICY_FILES, WEIGHTS, write_manifest
from satenv.training.trust import UntrustedDataError, read_member, safetensors_arrays, sha256_file

SECRET = "TOP-SECRET-7f3a9c"
MEMBERS = (*POLICY_FILES, MANIFEST)
FAST = settings(max_examples=25, deadline=None, suppress_health_check=list(HealthCheck))


@pytest.fixture
def folder(tmp_path):
    return good_policy_folder(tmp_path / "p")


@pytest.fixture
def outside(tmp_path):
    path = tmp_path / "secret.txt"
    path.write_text(json.dumps({"format": SECRET, "sha256": SECRET}) + SECRET * 10)
    return path


def _refused(root, match: str, **kwargs) -> str:
    with pytest.raises(training.PolicyLoadError, match=match) as info:
        training.load(root, **kwargs)
    return str(info.value)


# ------------------------------------------------------------------- the good folder
def test_save_writes_safetensors_and_a_manifest_and_loads_bit_for_bit(folder):
    names = {p.name for p in folder.iterdir()}
    assert WEIGHTS in names and MANIFEST in names and LEGACY_WEIGHTS not in names
    listed = json.loads((folder / MANIFEST).read_text())["sha256"]
    assert set(listed) == set(POLICY_FILES)
    assert all(listed[n] == sha256_file(folder / n) for n in POLICY_FILES)
    policy = training.load(folder)
    obs = np.random.default_rng(0).normal(size=(5, 6))
    assert np.array_equal(policy.predict(obs), training.load(folder).predict(obs))


def test_own_reader_matches_the_safetensors_library(folder):
    """The header-checked reader gives the tensors the reference implementation reads."""
    from safetensors.numpy import load_file

    ref = load_file(str(folder / WEIGHTS))
    shapes = {k: v.shape for k, v in ref.items()}
    mine = safetensors_arrays(read_member(folder, WEIGHTS, 2**20), shapes, WEIGHTS)
    assert set(mine) == set(ref) and all(np.array_equal(mine[k], ref[k]) for k in ref)


def test_every_shipped_policy_has_the_safe_format_and_loads():
    for root in sorted(p for p in training.POLICIES_DIR.iterdir() if p.is_dir()):
        assert (root / WEIGHTS).is_file() and (root / MANIFEST).is_file(), root.name
        assert not (root / LEGACY_WEIGHTS).exists(), root.name
        training.load(root, shielded=False)   # the network (a filtered folder needs env= for the filter)


# ------------------------------------------------------------------- nothing outside the folder
@pytest.mark.parametrize("name", MEMBERS)
def test_a_link_in_place_of_any_member_is_refused_without_reading_it(folder, outside, name):
    (folder / name).unlink()
    (folder / name).symlink_to(outside)
    msg = _refused(folder, "symbolic link", trusted=name == MANIFEST)
    assert name in msg and SECRET not in msg


def test_a_link_pointing_inside_the_folder_is_refused_too(folder):
    (folder / "copy.json").write_bytes((folder / "env.json").read_bytes())
    (folder / "env.json").unlink()
    (folder / "env.json").symlink_to(folder / "copy.json")
    _refused(folder, "env.json: is a symbolic link")


def test_a_linked_folder_is_read_where_it_points(folder, tmp_path):
    """The folder path itself may be a link (runs/latest -> runs/x): its members are checked."""
    (tmp_path / "latest").symlink_to(folder)
    training.load(tmp_path / "latest")


@pytest.mark.parametrize("name", MEMBERS)
def test_a_directory_or_fifo_in_place_of_a_member_is_refused_without_hanging(folder, name):
    (folder / name).unlink()
    os.mkfifo(folder / name)
    t0 = time.perf_counter()
    _refused(folder, f"{name}: is not a regular file")
    assert time.perf_counter() - t0 < 5
    (folder / name).unlink()
    (folder / name).mkdir()
    _refused(folder, f"{name}: is not a regular file")


@pytest.mark.parametrize("name", MEMBERS)
def test_a_sparse_giant_member_is_refused_from_its_size(folder, name):
    """An 8 GB (sparse) file is refused from ``stat`` before a byte is read."""
    with open(folder / name, "r+b") as f:
        f.truncate(8 * 2**30)
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        _refused(folder, rf"{name}: \d+ bytes, more than the cap")
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert time.perf_counter() - t0 < 2 and peak < 2**24


# ------------------------------------------------------------------- header first
def _safetensors(header: dict, body: bytes) -> bytes:
    raw = json.dumps(header).encode()
    return struct.pack("<Q", len(raw)) + raw + body


def test_a_header_declaring_a_huge_tensor_allocates_nothing(folder):
    """The audit's case: a small file whose header declares 2**30 elements (4.3 GB)."""
    header = {k: {"dtype": "F32", "shape": [2**15, 2**15], "data_offsets": [0, 4 * 2**30]}
              for k in ("body.0.weight",)}
    (folder / WEIGHTS).write_bytes(_safetensors(header, b"\0" * 4_200_000))
    write_manifest(folder)
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        _refused(folder, WEIGHTS)
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert time.perf_counter() - t0 < 2 and peak < 2**24


def test_a_policy_json_asking_for_a_giant_actor_allocates_nothing(folder):
    spec = json.loads((folder / "policy.json").read_text())
    spec["actor"]["hidden"] = [4096] * 60
    (folder / "policy.json").write_text(json.dumps(spec))
    write_manifest(folder)
    tracemalloc.start()
    try:
        _refused(folder, "policy.json|weights")
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert peak < 2**24


_ENTRY = st.fixed_dictionaries({
    "dtype": st.sampled_from(["F32", "F64", "F16", "I64", "BOOL", "U8", 7, None]),
    "shape": st.one_of(st.lists(st.integers(-2, 2**40), max_size=4), st.just([8, 6]), st.text(max_size=3)),
    "data_offsets": st.one_of(st.lists(st.integers(-10, 2**40), min_size=0, max_size=3),
                              st.just([0, 192]), st.just("0")),
})


@FAST
@given(entries=st.dictionaries(st.sampled_from(["body.0.weight", "body.0.bias", "head.weight", "head.bias",
                                                "x", "__metadata__"]), _ENTRY, max_size=5),
       body=st.integers(0, 4096), header_len=st.one_of(st.none(), st.integers(0, 2**64 - 1)))
def test_random_safetensors_headers_are_refused_or_exact(tmp_path_factory, entries, body, header_len):
    root = good_policy_folder(tmp_path_factory.mktemp("h") / "p")
    data = _safetensors(entries, b"\0" * body)
    if header_len is not None:
        data = struct.pack("<Q", header_len) + data[8:]
    (root / WEIGHTS).write_bytes(data)
    write_manifest(root)
    t0 = time.perf_counter()
    try:
        training.load(root)
    except training.PolicyLoadError as exc:
        assert WEIGHTS in str(exc) or "policy.json" in str(exc)
    assert time.perf_counter() - t0 < 2


# ------------------------------------------------------------------- the manifest
def test_a_missing_manifest_needs_trusted_true_which_says_what_it_skips(folder):
    (folder / MANIFEST).unlink()
    _refused(folder, "manifest.json: missing.*trusted=True")
    with pytest.warns(UserWarning, match="changed files are not detected"):
        training.load(folder, trusted=True)


def test_a_manifest_replaced_by_a_directory_is_refused_even_when_trusted(folder):
    (folder / MANIFEST).unlink()
    (folder / MANIFEST).mkdir()
    _refused(folder, "manifest.json: is not a regular file", trusted=True)


@FAST
@given(name=st.sampled_from(POLICY_FILES), where=st.floats(0, 1), byte=st.integers(1, 255))
def test_any_changed_byte_is_detected(tmp_path_factory, name, where, byte):
    root = good_policy_folder(tmp_path_factory.mktemp("m") / "p")
    data = bytearray((root / name).read_bytes())
    i = min(int(where * len(data)), len(data) - 1)
    data[i] ^= byte
    (root / name).write_bytes(bytes(data))
    _refused(root, rf"\['{name}'\] do not match manifest.json")


def test_a_manifest_that_does_not_list_a_file_is_refused(folder):
    listed = json.loads((folder / MANIFEST).read_text())
    del listed["sha256"]["env.json"]
    (folder / MANIFEST).write_text(json.dumps(listed))
    _refused(folder, r"manifest.json: does not list \['env.json'\]")


# ------------------------------------------------------------------- errors name, never echo
@FAST
@given(name=st.sampled_from(MEMBERS), junk=st.sampled_from([
    SECRET, json.dumps(SECRET), json.dumps({"format": SECRET}), json.dumps([SECRET] * 3),
    json.dumps({"identity": SECRET}), json.dumps({"sha256": {SECRET: SECRET}}), "[" * 100_000 + SECRET,
    json.dumps({"format": "satenv-policy/1", "actor": {"type": SECRET}})]))
def test_errors_name_the_file_and_never_echo_its_content(tmp_path_factory, name, junk):
    root = good_policy_folder(tmp_path_factory.mktemp("e") / "p")
    (root / name).write_text(junk)
    if name != MANIFEST:
        write_manifest(root)
    try:
        training.load(root)  # e.g. env.json: any object is metadata
    except training.PolicyLoadError as exc:
        assert SECRET not in str(exc)
        assert any(n in str(exc) for n in MEMBERS), str(exc)
    else:
        assert name in ("env.json", "config.json")


def test_a_legacy_folder_is_refused_unless_trusted_and_converts(folder):
    import torch

    from satenv.training.policy import convert_weights_pt

    policy = training.load(folder)
    torch.save(dict(policy.actor.state_dict()), folder / LEGACY_WEIGHTS)
    (folder / WEIGHTS).unlink()
    write_manifest(folder)
    _refused(folder, "weights.pt: the legacy torch format")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        old = training.load(folder, trusted=True)
    convert_weights_pt(folder)
    assert not (folder / LEGACY_WEIGHTS).exists()
    obs = np.random.default_rng(1).normal(size=(4, 6))
    assert np.array_equal(training.load(folder).predict(obs), old.predict(obs))


def test_read_member_refuses_names_that_leave_the_folder(folder):
    for name in ("../p/env.json", "/etc/hostname", "..", "", "a\0b", f"{folder}/env.json"):
        with pytest.raises(UntrustedDataError, match="plain file name"):
            read_member(folder, name, 2**20)
