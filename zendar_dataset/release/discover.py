"""Finding scenes and stream files in a release folder.

Users reported one scene per ``<YYYY-MM-DD_HHMM>/<NNN>/`` folder (also
flattened as ``<YYYY-MM-DD_HHMM>_<NNN>``), with streams in the folder and in
sub-folders (``range_Doppler/left_rd.pbs``, ``lidar/00/stream.pbs``).  A
stream belongs to the nearest such folder above it, looked for along the whole
path (also above the source folder: one scene folder imported alone keeps its
date); streams under no such folder form one scene named after the source folder.

:func:`fingerprint` identifies a recording by its streams' content (not their
paths), so that a re-import can tell a moved copy from a different recording.
"""

from __future__ import annotations

import hashlib
import os
import pathlib
import re
from dataclasses import dataclass, field

_DATE_TIME = re.compile(r"^\d{4}-\d{2}-\d{2}_\d{4,6}$")
_NUMBER = re.compile(r"^\d{1,4}$")
_FLAT = re.compile(r"^\d{4}-\d{2}-\d{2}_\d{4,6}_\d{1,4}$")
_BAD_ID = re.compile(r"[^A-Za-z0-9._-]+")
STREAM_SUFFIXES = (".pbs", ".pbs.gz", ".pb")


@dataclass
class SceneSource:
    """One scene of a release: its id, folder and stream files (sorted)."""

    scene_id: str
    folder: pathlib.Path
    files: list[pathlib.Path] = field(default_factory=list)


def is_stream_file(path: pathlib.Path) -> bool:
    """``*.pbs``, ``*.pbs.gz`` (length-prefixed streams) or ``*.pb`` (one message)."""
    return path.is_file() and path.name.lower().endswith(STREAM_SUFFIXES)


def _scene_of(path: pathlib.Path) -> tuple[str, pathlib.Path] | None:
    for folder in path.parents:
        if _FLAT.match(folder.name):
            return folder.name, folder
        if _NUMBER.match(folder.name) and _DATE_TIME.match(folder.parent.name):
            return f"{folder.parent.name}_{folder.name}", folder
    return None


def scene_id_from_name(name: str) -> str:
    """A format-v1 scene id (no ``/``, not starting with ``.``) from a folder name."""
    cleaned = _BAD_ID.sub("_", name).lstrip(".") or "scene"
    return cleaned


def find_scenes(src: pathlib.Path) -> list[SceneSource]:
    """Every scene under ``src`` with its stream files, in id order (empty when none)."""
    src = src.resolve()
    scenes: dict[str, SceneSource] = {}
    files = [src] if src.is_file() else sorted(p for p in src.rglob("*") if is_stream_file(p))
    for path in files:
        found = _scene_of(path)
        if found is None:
            base = src if src.is_dir() else src.parent
            found = (scene_id_from_name(base.name), base)
        scene_id, folder = found
        scenes.setdefault(scene_id, SceneSource(scene_id, folder)).files.append(path)
    return [scenes[k] for k in sorted(scenes)]


FINGERPRINT_SAMPLES = 16
FINGERPRINT_SAMPLE_BYTES = 64 * 2**10


def _file_digest(path: pathlib.Path) -> bytes:
    """SHA-256 over the file's size and 16 evenly spaced 64 KiB samples (first and last included), or all
    of it when that is no more (reading whole multi-GB scenes would cost more than the import's check is worth)."""
    size = path.stat().st_size
    digest = hashlib.sha256(str(size).encode())
    with open(path, "rb") as handle:
        if size <= FINGERPRINT_SAMPLES * FINGERPRINT_SAMPLE_BYTES:
            digest.update(handle.read())
        else:
            last = size - FINGERPRINT_SAMPLE_BYTES
            for k in range(FINGERPRINT_SAMPLES):
                handle.seek(last * k // (FINGERPRINT_SAMPLES - 1), os.SEEK_SET)
                digest.update(handle.read(FINGERPRINT_SAMPLE_BYTES))
    return digest.digest()


def fingerprint(files: list[pathlib.Path]) -> str:
    """``sha256:<hex>`` of a scene's stream files by content: their per-file digests, sorted (so
    neither the files' paths nor their order count; a moved or renamed copy has the same fingerprint)."""
    combined = hashlib.sha256(b"".join(sorted(_file_digest(path) for path in files)))
    return f"sha256:{combined.hexdigest()}"
