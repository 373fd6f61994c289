"""Finding scenes and stream files in a release folder.

Users reported one scene per ``<YYYY-MM-DD_HHMM>/<NNN>/`` folder (also
flattened as ``<YYYY-MM-DD_HHMM>_<NNN>``), with streams in the folder and in
sub-folders (``range_Doppler/left_rd.pbs``, ``lidar/00/stream.pbs``).  A
stream belongs to the nearest such folder above it; streams under no such
folder form one scene named after the source folder.
"""

from __future__ import annotations

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


def _scene_of(path: pathlib.Path, src: pathlib.Path) -> tuple[str, pathlib.Path] | None:
    for folder in path.parents:
        if folder == src.parent:
            break
        if _FLAT.match(folder.name):
            return folder.name, folder
        if _NUMBER.match(folder.name) and _DATE_TIME.match(folder.parent.name) and folder.parent != src.parent:
            return f"{folder.parent.name}_{folder.name}", folder
        if folder == src:
            break
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
        found = _scene_of(path, src if src.is_dir() else src.parent)
        if found is None:
            base = src if src.is_dir() else src.parent
            found = (scene_id_from_name(base.name), base)
        scene_id, folder = found
        scenes.setdefault(scene_id, SceneSource(scene_id, folder)).files.append(path)
    return [scenes[k] for k in sorted(scenes)]
