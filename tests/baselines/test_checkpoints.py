"""Checkpoints: atomic write, SHA-256 manifest, and every refusal of load_checkpoint."""

from __future__ import annotations

import hashlib
import json
import os

import pytest
import torch

from zendar_baselines.cnn.checkpoints import (
    CHECKPOINT_FORMAT,
    MANIFEST_NAME,
    CheckpointError,
    load_checkpoint,
    save_checkpoint,
)
from zendar_baselines.code_version import code_version
from zendar_dataset.errors import ZendarError

from tests.baselines.tiny_mask_model import TinyMaskNet


def _saved(tmp_path, name="epoch-0001.pt", model=None, **extra):
    torch.manual_seed(0)
    model = model or TinyMaskNet(in_channels=2)
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-3)
    model(torch.ones(1, 2, 4, 4)).sum().backward()
    optimizer.step()
    path = tmp_path / name
    save_checkpoint(path, model, optimizer, 1, {"seed": 3}, extra or {"losses": [0.5]})
    return path, model, optimizer


def test_round_trip_and_manifest(tmp_path):
    path, model, optimizer = _saved(tmp_path)
    manifest = json.loads((tmp_path / MANIFEST_NAME).read_text())
    assert manifest == {path.name: hashlib.sha256(path.read_bytes()).hexdigest()}
    assert sorted(os.listdir(tmp_path)) == sorted([MANIFEST_NAME, path.name])  # no temporaries left
    # Readable without our loader, with no code run while unpickling.
    raw = torch.load(path, weights_only=True)
    assert raw["format"] == CHECKPOINT_FORMAT and raw["format_version"] == 1
    checkpoint = load_checkpoint(path, expected_architecture=model.architecture)
    assert checkpoint["code_version"] == code_version()
    assert checkpoint["epoch"] == 1 and checkpoint["config"] == {"seed": 3} and checkpoint["losses"] == [0.5]
    assert checkpoint["optimizer_state"]["state"][0]["step"] == 1
    fresh = TinyMaskNet(in_channels=2)
    load_checkpoint(path, model=fresh)
    for name, tensor in model.state_dict().items():
        assert torch.equal(fresh.state_dict()[name], tensor)


def test_manifest_keeps_every_file(tmp_path):
    first, _, _ = _saved(tmp_path, "epoch-0001.pt")
    second, _, _ = _saved(tmp_path, "epoch-0002.pt")
    manifest = json.loads((tmp_path / MANIFEST_NAME).read_text())
    assert set(manifest) == {first.name, second.name}
    load_checkpoint(first)
    load_checkpoint(second)


def test_flipped_byte_is_refused_naming_the_file(tmp_path):
    path, _, _ = _saved(tmp_path)
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0x01
    path.write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match=rf"{path.name}: SHA-256 [0-9a-f]{{64}} does not match") as excinfo:
        load_checkpoint(path)
    assert str(path) in str(excinfo.value)


def test_wrong_architecture_names_both(tmp_path):
    path, _, _ = _saved(tmp_path)
    expected = {"name": "densenet-37", "in_channels": 12, "width_scale": 0.25}
    with pytest.raises(ZendarError) as excinfo:
        load_checkpoint(path, expected_architecture=expected)
    message = str(excinfo.value)
    assert str(path) in message and "tiny-mask-net" in message and "densenet-37" in message


def test_state_that_does_not_fit_names_the_keys(tmp_path):
    path, _, _ = _saved(tmp_path)
    with pytest.raises(CheckpointError, match=r"does not fit.*features\.weight \(8, 2, 3, 3\) vs model \(4, 2, 3, 3\)"):
        load_checkpoint(path, model=TinyMaskNet(in_channels=2, width=4))


def test_missing_file(tmp_path):
    with pytest.raises(CheckpointError, match="epoch-0009.pt: checkpoint not found"):
        load_checkpoint(tmp_path / "epoch-0009.pt")


def test_file_absent_from_manifest(tmp_path):
    path, _, _ = _saved(tmp_path)
    (tmp_path / MANIFEST_NAME).write_text("{}")
    with pytest.raises(CheckpointError, match="not listed in"):
        load_checkpoint(path)


def _vouch(path):
    manifest_path = path.parent / MANIFEST_NAME
    manifest = json.loads(manifest_path.read_text()) if manifest_path.exists() else {}
    manifest[path.name] = hashlib.sha256(path.read_bytes()).hexdigest()
    manifest_path.write_text(json.dumps(manifest))


def test_non_checkpoint_files(tmp_path):
    plain = tmp_path / "plain.pt"
    torch.save({"weights": torch.zeros(2)}, plain)
    text = tmp_path / "text.pt"
    text.write_text("hello")
    for path in (plain, text):
        _vouch(path)
        with pytest.raises(CheckpointError, match=rf"{path.name}: not a {CHECKPOINT_FORMAT} file"):
            load_checkpoint(path)


def test_code_objects_are_not_unpickled(tmp_path):
    # A pickle that would call a function on load is refused by weights_only before anything runs.
    path = tmp_path / "evil.pt"
    torch.save({"format": CHECKPOINT_FORMAT, "hook": print}, path)
    _vouch(path)
    with pytest.raises(CheckpointError, match="not a zendar-bench-checkpoint file"):
        load_checkpoint(path)


def test_other_format_version(tmp_path):
    path, _, _ = _saved(tmp_path)
    checkpoint = torch.load(path, weights_only=True)
    checkpoint["format_version"] = 2
    torch.save(checkpoint, path)
    _vouch(path)
    with pytest.raises(CheckpointError, match="format version 2; this code reads version 1"):
        load_checkpoint(path)


def test_unstorable_values_are_refused_before_writing(tmp_path):
    model = TinyMaskNet(in_channels=2)
    optimizer = torch.optim.Adam(model.parameters())
    with pytest.raises(CheckpointError, match=r"\['note'\] is a set"):
        save_checkpoint(tmp_path / "a.pt", model, optimizer, 1, {}, {"note": {1, 2}})
    with pytest.raises(CheckpointError, match="replace the checkpoint's own keys"):
        save_checkpoint(tmp_path / "a.pt", model, optimizer, 1, {}, {"epoch": 3})
    del model.architecture
    with pytest.raises(CheckpointError, match="no architecture"):
        save_checkpoint(tmp_path / "a.pt", model, optimizer, 1, {}, {})
    assert os.listdir(tmp_path) == []
