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

from zendar_dataset.errors import ZendarError

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


def stream_files(src: pathlib.Path) -> list[pathlib.Path]:
    """The stream files under the folder ``src``, sorted, following linked folders (a release put
    together from links to its scenes) and entering each real folder once (a link to a folder above
    would otherwise loop)."""
    visited: set[tuple[int, int]] = set()
    found = []
    for folder, subfolders, names in os.walk(src, followlinks=True):
        status = os.stat(folder)
        if (status.st_dev, status.st_ino) in visited:
            subfolders.clear()
            continue
        visited.add((status.st_dev, status.st_ino))
        found.extend(path for path in (pathlib.Path(folder, name) for name in names) if is_stream_file(path))
    return sorted(found)


def find_scenes(src: pathlib.Path) -> list[SceneSource]:
    """Every scene under ``src`` with its stream files, in id order (empty when none).

    Scene ids come from the path as given (a linked folder is named as the link, not its target).

    Raises
    ------
    ZendarError
        When two different folders give the same scene id (e.g. ``a/2020-02-21_0900/001`` and
        ``b/2020-02-21_0900/001``, or a date folder's ``001`` and a flattened ``…_001``), all listed:
        they would be imported as one scene.
    """
    src = pathlib.Path(os.path.abspath(src))
    scenes: dict[str, SceneSource] = {}
    clashes: dict[str, set[pathlib.Path]] = {}
    for path in [src] if src.is_file() else stream_files(src):
        found = _scene_of(path)
        if found is None:
            base = src if src.is_dir() else src.parent
            found = (scene_id_from_name(base.name), base)
        scene_id, folder = found
        scene = scenes.setdefault(scene_id, SceneSource(scene_id, folder))
        if scene.folder != folder:
            clashes.setdefault(scene_id, {scene.folder}).add(folder)
            continue
        scene.files.append(path)
    if clashes:
        listed = "; ".join(f"{scene_id}: {', '.join(str(f) for f in sorted(folders))}" for scene_id, folders in sorted(clashes.items()))
        raise ZendarError(
            f"{src}: different folders give the same scene id ({listed}); import each of them on its own, "
            "with --scene-id to tell them apart"
        )
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
