"""Training checkpoints of the CNN baselines: written atomically, listed with their SHA-256, loaded safely.

A checkpoint is one ``torch.save`` file holding only tensors, dicts, lists, numbers and strings, so
it loads with ``torch.load(..., weights_only=True)`` (no code runs while reading it)::

    {"format": "zendar-bench-checkpoint", "format_version": 1, "code_version": str,
     "architecture": {"name", "in_channels", "width_scale"}, "config": dict, "epoch": int,
     "model_state": {name: Tensor}, "optimizer_state": dict, "rng_state": dict, **extra}

Every checkpoint directory holds ``manifest.json`` (file name → SHA-256 hex of its bytes), updated
atomically after each write; a checkpoint whose bytes no longer match is refused, so a file cut
short by a full disk or altered by hand is never trained on or evaluated.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch
from torch import nn

from zendar_dataset.errors import ZendarError
from zendar_dataset.atomic_files import json_text, write_bytes_atomic, write_text_atomic

from zendar_baselines.code_version import code_version

CHECKPOINT_FORMAT = "zendar-bench-checkpoint"
CHECKPOINT_FORMAT_VERSION = 1
MANIFEST_NAME = "manifest.json"
_REQUIRED_KEYS = ("code_version", "architecture", "config", "epoch", "model_state", "optimizer_state", "rng_state")
_HASH_BLOCK_BYTES = 1 << 20


class CheckpointError(ZendarError):
    """A checkpoint file is missing, altered, of another format or architecture, or does not fit a model."""


class CheckpointIntegrityError(CheckpointError):
    """A checkpoint's bytes are not vouched for by its directory's manifest (absent from it, or another SHA-256)."""


def unwrap_model(model: nn.Module) -> nn.Module:
    """The module inside a ``DistributedDataParallel`` wrapper, else ``model`` itself."""
    return model.module if isinstance(model, nn.parallel.DistributedDataParallel) else model


def model_architecture(model: nn.Module) -> dict[str, Any]:
    """``model.architecture`` (``{"name", "in_channels", "width_scale"}``) as a plain dict.

    Raises
    ------
    CheckpointError
        When the model has no ``architecture`` dict.
    """
    architecture = getattr(unwrap_model(model), "architecture", None)
    if not isinstance(architecture, Mapping):
        raise CheckpointError(
            f"model {type(unwrap_model(model)).__name__} has no architecture dict "
            "(expected model.architecture = {'name', 'in_channels', 'width_scale'})"
        )
    return dict(architecture)


def file_sha256(path: Path) -> str:
    """SHA-256 hex digest of a file's bytes, read in 1 MiB blocks."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(_HASH_BLOCK_BYTES), b""):
            digest.update(block)
    return digest.hexdigest()


def read_manifest(directory: Path) -> dict[str, str]:
    """``manifest.json`` of a checkpoint directory (file name → SHA-256 hex); empty when absent.

    Raises
    ------
    CheckpointError
        When the manifest exists but is not a JSON object of strings.
    """
    path = Path(directory) / MANIFEST_NAME
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return {}
    try:
        manifest = json.loads(text)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CheckpointError(f"{path}: not a checkpoint manifest (invalid JSON: {exc})") from None
    if not isinstance(manifest, dict) or not all(isinstance(v, str) for v in manifest.values()):
        raise CheckpointError(f"{path}: not a checkpoint manifest (expected an object of file name → sha256 hex)")
    return manifest


def _check_storable(value: Any, where: str) -> None:
    # Only what torch.load(weights_only=True) accepts back; anything else would make the file unloadable.
    if value is None or isinstance(value, (bool, int, float, str, torch.Tensor)):
        return
    if isinstance(value, (list, tuple)):
        for index, item in enumerate(value):
            _check_storable(item, f"{where}[{index}]")
        return
    if isinstance(value, dict):
        for key, item in value.items():
            if not isinstance(key, (str, int)):
                raise CheckpointError(f"checkpoint {where}: key {key!r} is a {type(key).__name__}; use str or int keys")
            _check_storable(item, f"{where}[{key!r}]")
        return
    raise CheckpointError(
        f"checkpoint {where} is a {type(value).__name__}; store only tensors, dicts, lists, numbers and strings"
    )


def save_checkpoint(
    path: str | os.PathLike,
    model: nn.Module,
    optimizer: torch.optim.Optimizer,
    epoch: int,
    config: Mapping[str, Any],
    extra: Mapping[str, Any] | None = None,
) -> str:
    """Write a checkpoint atomically (temporary sibling + rename) and record its SHA-256 in the manifest.

    Parameters
    ----------
    path
        The checkpoint file; its directory must exist and receives ``manifest.json``.
    model
        The trained model (a ``DistributedDataParallel`` wrapper is unwrapped); must carry
        ``model.architecture``. Its state is stored on the CPU.
    optimizer
        Its ``state_dict()`` is stored.
    epoch
        Epochs completed (1 after the first).
    config
        JSON-like description of the run (schedule, seed, data…), stored as ``"config"``.
    extra
        More top-level entries (e.g. per-epoch losses, ``rng_state``); may not replace the format keys.

    Returns
    -------
    str
        SHA-256 hex of the file written.

    Raises
    ------
    CheckpointError
        When a value cannot be stored for a ``weights_only`` load, or ``extra`` names a reserved key.
    """
    path = Path(path)
    extra = dict(extra or {})
    reserved = {"format", "format_version", "architecture", "config", "epoch", "model_state", "optimizer_state", "code_version"}
    clash = sorted(reserved & set(extra))
    if clash:
        raise CheckpointError(f"{path}: extra entries {clash} would replace the checkpoint's own keys")
    payload: dict[str, Any] = {
        "format": CHECKPOINT_FORMAT,
        "format_version": CHECKPOINT_FORMAT_VERSION,
        "code_version": code_version(),
        "architecture": model_architecture(model),
        "config": dict(config),
        "epoch": int(epoch),
        "model_state": {name: tensor.detach().cpu() for name, tensor in unwrap_model(model).state_dict().items()},
        "optimizer_state": optimizer.state_dict(),
        "rng_state": {},  # replaced by extra["rng_state"] when the caller records one
        **extra,
    }
    _check_storable(payload, "")
    buffer = io.BytesIO()
    torch.save(payload, buffer)
    data = buffer.getvalue()
    sha256 = hashlib.sha256(data).hexdigest()
    write_bytes_atomic(path, data)
    # The manifest follows the file: a run killed in between leaves a checkpoint the manifest does
    # not vouch for, which load_checkpoint refuses and training recomputes.
    manifest = read_manifest(path.parent)
    manifest[path.name] = sha256
    write_text_atomic(path.parent / MANIFEST_NAME, json_text(manifest, indent=2, sort_keys=True))
    return sha256


def remove_checkpoint(path: str | os.PathLike) -> None:
    """Delete a checkpoint: first its manifest entry (atomically), then the file; absent ones are fine.

    In this order an interruption leaves at worst a file the manifest no longer vouches for, which
    :func:`load_checkpoint` refuses, never a manifest entry whose file is half deleted.
    """
    path = Path(path)
    manifest = read_manifest(path.parent)
    if manifest.pop(path.name, None) is not None:
        write_text_atomic(path.parent / MANIFEST_NAME, json_text(manifest, indent=2, sort_keys=True))
    path.unlink(missing_ok=True)


def _architecture_text(architecture: Any) -> str:
    return json.dumps(architecture, sort_keys=True, default=str)


def load_model_state(model: nn.Module, checkpoint: Mapping[str, Any], path: str | os.PathLike) -> None:
    """Copy a checkpoint's ``model_state`` into ``model`` (strictly: every key, every shape).

    Raises
    ------
    CheckpointError
        Naming the file and the keys missing, unexpected or of another shape.
    """
    target = unwrap_model(model)
    state = checkpoint["model_state"]
    expected = target.state_dict()
    missing = sorted(set(expected) - set(state))
    unexpected = sorted(set(state) - set(expected))
    reshaped = [
        f"{name} {tuple(state[name].shape)} vs model {tuple(tensor.shape)}"
        for name, tensor in expected.items()
        if name in state and isinstance(state[name], torch.Tensor) and state[name].shape != tensor.shape
    ]
    if missing or unexpected or reshaped:
        problems = []
        if missing:
            problems.append(f"missing {missing[:5]}{' …' if len(missing) > 5 else ''}")
        if unexpected:
            problems.append(f"unexpected {unexpected[:5]}{' …' if len(unexpected) > 5 else ''}")
        if reshaped:
            problems.append(f"other shapes: {'; '.join(reshaped[:5])}{' …' if len(reshaped) > 5 else ''}")
        raise CheckpointError(
            f"{path}: model state does not fit {type(target).__name__} "
            f"({_architecture_text(getattr(target, 'architecture', None))}): {', '.join(problems)}"
        )
    target.load_state_dict(state, strict=True)


def load_checkpoint(
    path: str | os.PathLike,
    expected_architecture: Mapping[str, Any] | None = None,
    *,
    model: nn.Module | None = None,
) -> dict[str, Any]:
    """Read a checkpoint after checking its SHA-256 against the directory's manifest.

    Parameters
    ----------
    path
        A file written by :func:`save_checkpoint`.
    expected_architecture
        When given, the stored ``architecture`` must equal it.
    model
        When given, the stored ``model_state`` is loaded into it (strictly).

    Returns
    -------
    dict
        The checkpoint, tensors on the CPU.

    Raises
    ------
    CheckpointError
        Naming the file: missing; not listed in, or not matching, ``manifest.json``; not a
        checkpoint; another format version; another architecture than expected (both named); a
        model state that does not fit ``model``.
    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{path}: checkpoint not found" + (" (a directory)" if path.is_dir() else ""))
    manifest = read_manifest(path.parent)
    recorded = manifest.get(path.name)
    if recorded is None:
        raise CheckpointIntegrityError(
            f"{path}: not listed in {path.parent / MANIFEST_NAME}; its integrity cannot be checked "
            "(an interrupted write, or a file copied without its manifest)"
        )
    actual = file_sha256(path)
    if actual != recorded:
        raise CheckpointIntegrityError(
            f"{path}: SHA-256 {actual} does not match {recorded} recorded in {path.parent / MANIFEST_NAME}; "
            "the file was altered or cut short"
        )
    try:
        checkpoint = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - whatever a foreign file makes the unpickler raise means "not ours"
        raise CheckpointError(f"{path}: not a {CHECKPOINT_FORMAT} file ({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})") from None
    if not isinstance(checkpoint, dict) or checkpoint.get("format") != CHECKPOINT_FORMAT:
        found = checkpoint.get("format") if isinstance(checkpoint, dict) else type(checkpoint).__name__
        raise CheckpointError(f"{path}: not a {CHECKPOINT_FORMAT} file (format {found!r})")
    version = checkpoint.get("format_version")
    if version != CHECKPOINT_FORMAT_VERSION:
        raise CheckpointError(
            f"{path}: checkpoint format version {version!r}; this code reads version {CHECKPOINT_FORMAT_VERSION}"
        )
    absent = [key for key in _REQUIRED_KEYS if key not in checkpoint]
    if absent:
        raise CheckpointError(f"{path}: checkpoint lacks {absent}")
    if expected_architecture is not None and dict(checkpoint["architecture"]) != dict(expected_architecture):
        raise CheckpointError(
            f"{path}: checkpoint of architecture {_architecture_text(checkpoint['architecture'])}, "
            f"expected {_architecture_text(dict(expected_architecture))}"
        )
    if model is not None:
        load_model_state(model, checkpoint, path)
    return checkpoint


__all__ = [
    "CHECKPOINT_FORMAT",
    "CHECKPOINT_FORMAT_VERSION",
    "MANIFEST_NAME",
    "CheckpointError",
    "CheckpointIntegrityError",
    "file_sha256",
    "load_checkpoint",
    "load_model_state",
    "model_architecture",
    "read_manifest",
    "remove_checkpoint",
    "save_checkpoint",
    "unwrap_model",
]
