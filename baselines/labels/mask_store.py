"""A versioned side store of dynamic-object masks, next to (never inside) the dataset it labels: the
automatic labels, or the manual-label masks of the labelled part (the same format; its errors call it
an "auto-label store" either way).

Layout of the store directory::

    manifest.json          what made the store and what it holds (below)
    <scene_id>.npz         per radar: "<radar>/timestamp_ns" int64 [N] and "<radar>/masks" uint8 [N, R, D]

``manifest.json``::

    {"format": "zendar-autolabels", "format_version": 1,
     "code_version": "<zendar_baselines.code_version.code_version()>",
     "parameters": {...},                                   # the labelling parameters, JSON
     "dataset": {"root": "<absolute path>", "fingerprint": "<SHA-256 of dataset.json bytes>"},
     "scenes": {"<scene_id>": {"file": "<scene_id>.npz", "sha256": "<of the file's bytes>",
                               "radars": {"<radar>": {"n_frames": N, "shape": [N, R, D]}}}},
     "created_utc": "<ISO 8601>"}

Every file is written under a temporary name and renamed into place, and the manifest is rewritten
after each scene, so a run stopped at any point keeps every scene it finished. The store belongs to
one dataset (its fingerprint), one set of parameters and one code version: :meth:`MaskStore.create`
on a store made with other parameters or code starts it over (removing only the scene files its own
manifest lists); a directory without our manifest, a store of another dataset and a store of another
format version are refused with nothing touched. One process writes a store at a time.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import zipfile
from collections.abc import Mapping
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from zendar_dataset.errors import ZendarError
from zendar_dataset.atomic_files import json_text, prepare_out_dir, write_bytes_atomic, write_text_atomic
from zendar_dataset.format import stores
from zendar_dataset.format.reader import DatasetIndex
from zendar_dataset.output_location import refuse_output_inside
from zendar_dataset.temporary_files import owner_pid, remove_stale_temporaries

from zendar_baselines.code_version import code_version as current_code_version
from zendar_baselines.fingerprints import SHA256_HEX, dataset_fingerprint, dataset_index, dataset_location
from zendar_baselines.labels.mask_classes import MASK_CLASSES, MASK_DTYPE

FORMAT_NAME = "zendar-autolabels"
FORMAT_VERSION = 1
MANIFEST_FILENAME = "manifest.json"
SCENE_SUFFIX = ".npz"
_FOREIGN_SHOWN = 5

RadarMasks = dict[str, tuple[np.ndarray, np.ndarray]]


class MaskStoreError(ZendarError):
    """An automatic-label store cannot be used; ``problems`` lists every problem found."""


def _raise_problems(problems: list[str]) -> None:
    if problems:
        raise MaskStoreError("; ".join(problems), problems)


def _valid_name(name: Any) -> bool:
    # The same rule as dataset.json's scene ids: a plain file-name component.
    return isinstance(name, str) and bool(name) and "/" not in name and "\\" not in name and not name.startswith(".")


def _canonical_parameters(parameters: Any) -> dict[str, Any]:
    """``parameters`` as they read back from JSON (tuples become lists), so comparisons are exact."""
    if not isinstance(parameters, Mapping):
        raise ZendarError(f"parameters: expected a JSON object (dict), found {type(parameters).__name__}")
    try:
        return json.loads(json.dumps(dict(parameters), allow_nan=False))
    except (TypeError, ValueError) as exc:
        raise ZendarError(f"parameters: expected JSON-serialisable values without NaN or infinity ({exc})") from None


def _root_text(dataset_root: str | os.PathLike) -> str:
    """The dataset root as recorded: absolute for a local path, as given for a URL."""
    return os.fspath(dataset_root) if stores.is_url(dataset_root) else str(Path(dataset_root).resolve())


def _make_directory(out: Path) -> None:
    try:
        prepare_out_dir(out)
    except OSError as exc:
        raise MaskStoreError(f"auto-label store {out}: cannot be created ({exc.strerror or exc})") from None


def _created_utc() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def _read_manifest(path: Path) -> Any:
    try:
        return json.loads(path.read_bytes().decode("utf-8"))
    except FileNotFoundError:
        raise MaskStoreError(f"{path}: expected the auto-label store's {MANIFEST_FILENAME}, found none") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise MaskStoreError(f"{path}: expected the auto-label store's JSON manifest, found unreadable content ({exc})") from None


def _check_shape(value: Any, n_frames: Any) -> bool:
    return (
        isinstance(value, list)
        and len(value) == 3
        and all(isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in value)
        and value[0] == n_frames
    )


def check_manifest(document: Any, where: str) -> list[str]:
    """Every way ``document`` differs from a format-1 auto-label manifest (empty when it is one).

    Parameters
    ----------
    document
        Parsed ``manifest.json``.
    where
        How the file is named in the problems (its path).
    """
    if not isinstance(document, dict):
        return [f"{where}: expected a JSON object, found {type(document).__name__}"]
    if document.get("format") != FORMAT_NAME:
        return [f"{where}: format: expected {FORMAT_NAME!r}, found {document.get('format')!r}"]
    if document.get("format_version") != FORMAT_VERSION:
        # Another version's layout is unknown: checking its fields would only add noise.
        return [
            f"{where}: format_version: expected {FORMAT_VERSION}, found {document.get('format_version')!r} "
            "(made by another version of zendar-bench)"
        ]
    problems = []
    if not isinstance(document.get("code_version"), str):
        problems.append(f"{where}: code_version: expected a string, found {document.get('code_version')!r}")
    if not isinstance(document.get("parameters"), dict):
        problems.append(f"{where}: parameters: expected a JSON object, found {document.get('parameters')!r}")
    if not isinstance(document.get("created_utc"), str):
        problems.append(f"{where}: created_utc: expected an ISO 8601 string, found {document.get('created_utc')!r}")
    dataset = document.get("dataset")
    if not isinstance(dataset, dict):
        problems.append(f"{where}: dataset: expected {{\"root\": ..., \"fingerprint\": ...}}, found {dataset!r}")
    else:
        if not isinstance(dataset.get("root"), str):
            problems.append(f"{where}: dataset.root: expected a path string, found {dataset.get('root')!r}")
        fingerprint = dataset.get("fingerprint")
        if not (isinstance(fingerprint, str) and SHA256_HEX.fullmatch(fingerprint)):
            problems.append(f"{where}: dataset.fingerprint: expected 64 lowercase hex digits, found {fingerprint!r}")
    scenes = document.get("scenes")
    if not isinstance(scenes, dict):
        problems.append(f"{where}: scenes: expected {{scene_id: {{...}}}}, found {scenes!r}")
        return problems
    for scene_id, entry in scenes.items():
        at = f"{where}: scenes.{scene_id}"
        if not _valid_name(scene_id):
            problems.append(f"{at}: expected a scene id without '/' and not starting with '.'")
            continue
        if not isinstance(entry, dict):
            problems.append(f"{at}: expected {{\"file\", \"sha256\", \"radars\"}}, found {entry!r}")
            continue
        if entry.get("file") != scene_id + SCENE_SUFFIX:
            problems.append(f"{at}.file: expected {scene_id + SCENE_SUFFIX!r}, found {entry.get('file')!r}")
        digest = entry.get("sha256")
        if not (isinstance(digest, str) and SHA256_HEX.fullmatch(digest)):
            problems.append(f"{at}.sha256: expected 64 lowercase hex digits, found {digest!r}")
        radars = entry.get("radars")
        if not isinstance(radars, dict) or not radars:
            problems.append(f"{at}.radars: expected {{radar: {{\"n_frames\", \"shape\"}}}} with at least one radar, found {radars!r}")
            continue
        for radar, record in radars.items():
            n_frames = record.get("n_frames") if isinstance(record, dict) else None
            shape = record.get("shape") if isinstance(record, dict) else None
            if not _valid_name(radar):
                problems.append(f"{at}.radars: expected radar names without '/', found {radar!r}")
            elif not (isinstance(n_frames, int) and not isinstance(n_frames, bool) and n_frames >= 0):
                problems.append(f"{at}.radars.{radar}.n_frames: expected a count >= 0, found {n_frames!r}")
            elif not _check_shape(shape, n_frames):
                problems.append(f"{at}.radars.{radar}.shape: expected [n_frames={n_frames}, R, D], found {shape!r}")
    return problems


def _member_headers(data: bytes) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """``{array name: (shape, dtype)}`` of an .npz file's bytes, reading only each array's header."""
    headers = {}
    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        for member in archive.namelist():
            with archive.open(member) as handle:
                version = np.lib.format.read_magic(handle)
                read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
                shape, _, dtype = read_header(handle)
            headers[member.removesuffix(".npy")] = (tuple(shape), dtype)
    return headers


def _expected_headers(radars: dict[str, dict]) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    expected = {}
    for radar, record in radars.items():
        expected[f"{radar}/timestamp_ns"] = ((record["n_frames"],), np.dtype(np.int64))
        expected[f"{radar}/masks"] = (tuple(record["shape"]), MASK_DTYPE)
    return expected


def _describe(header: tuple[tuple[int, ...], np.dtype] | None) -> str:
    return "nothing" if header is None else f"{header[1]} {list(header[0])}"


def _file_problems(path: Path, data: bytes, entry: dict) -> list[str]:
    """How a scene file's bytes differ from its manifest entry (checksum, then arrays)."""
    digest = hashlib.sha256(data).hexdigest()
    if digest != entry["sha256"]:
        return [
            f"{path}: SHA-256 {digest} differs from {entry['sha256']} recorded in {MANIFEST_FILENAME} "
            "(the file changed after it was written)"
        ]
    try:
        found = _member_headers(data)
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
        return [f"{path}: expected an .npz archive of mask arrays, found unreadable content ({exc})"]
    expected = _expected_headers(entry["radars"])
    return [
        f"{path}: {name}: expected {_describe(expected.get(name))} as recorded in {MANIFEST_FILENAME}, "
        f"found {_describe(found.get(name))}"
        for name in sorted(set(expected) | set(found))
        if expected.get(name) != found.get(name)
    ]


def _radar_masks_problems(scene_id: str, radar_masks: Any) -> list[str]:
    if not isinstance(radar_masks, Mapping) or not radar_masks:
        return [f"scene {scene_id}: expected {{radar: (timestamp_ns, masks)}} with at least one radar, found {radar_masks!r}"]
    problems = []
    for radar, pair in radar_masks.items():
        at = f"scene {scene_id} radar {radar}"
        if not _valid_name(radar):
            problems.append(f"scene {scene_id}: expected radar names without '/' and not starting with '.', found {radar!r}")
            continue
        if not (isinstance(pair, tuple | list) and len(pair) == 2):
            problems.append(f"{at}: expected a pair (timestamp_ns, masks)")
            continue
        timestamp_ns, masks = (np.asarray(value) for value in pair)
        if timestamp_ns.ndim != 1 or not np.issubdtype(timestamp_ns.dtype, np.integer):
            problems.append(f"{at}: timestamp_ns: expected integer nanoseconds [N], found {timestamp_ns.dtype} {list(timestamp_ns.shape)}")
        elif np.any(np.diff(timestamp_ns.astype(np.int64)) <= 0):
            problems.append(f"{at}: timestamp_ns: expected strictly increasing times, found a repeat or step back")
        if masks.ndim != 3 or masks.dtype != MASK_DTYPE:
            problems.append(f"{at}: masks: expected {MASK_DTYPE} [N, R, D], found {masks.dtype} {list(masks.shape)}")
            continue
        if timestamp_ns.ndim == 1 and masks.shape[0] != timestamp_ns.shape[0]:
            problems.append(f"{at}: expected one mask per timestamp, found {masks.shape[0]} masks and {timestamp_ns.shape[0]} timestamps")
        n_bad = int(np.count_nonzero(masks > max(MASK_CLASSES)))
        if n_bad:
            problems.append(f"{at}: masks: expected values in {list(MASK_CLASSES)}, found {n_bad} cells above {max(MASK_CLASSES)}")
    return problems


def _scene_problems(scene_id: Any, radar_masks: Any, dataset: tuple[str, frozenset[str]] | None) -> list[str]:
    problems = []
    if not _valid_name(scene_id):
        problems.append(f"scene id: expected a name without '/' and not starting with '.', found {scene_id!r}")
    elif dataset is not None and scene_id not in dataset[1]:
        problems.append(f"scene {scene_id}: not a scene of the dataset {dataset[0]}")
    return problems + _radar_masks_problems(str(scene_id), radar_masks)


def write_scene_file(directory: str | os.PathLike, scene_id: str, radar_masks: Mapping[str, tuple[np.ndarray, np.ndarray]],
                     dataset: tuple[str, frozenset[str]] | None = None) -> dict[str, Any]:
    """Write one scene's masks to ``directory / "<scene_id>.npz"`` atomically; return its manifest entry.

    The part of :meth:`MaskStore.write_scene` a worker on another host does: the file is complete at
    its final name or absent, and the manifest, which one process writes, records it afterwards
    (:meth:`MaskStore.record_scene`).

    Parameters
    ----------
    directory
        The store's directory.
    scene_id
        The scene's id (its file name).
    radar_masks
        As :meth:`MaskStore.write_scene`.
    dataset
        ``(root, scene ids)``: the scene must be one of them.

    Returns
    -------
    dict
        ``{"file", "sha256", "radars"}``, the scene's entry in the manifest.

    Raises
    ------
    MaskStoreError
        Listing every problem with the scene id or the arrays; nothing is written then.
    """
    _raise_problems(_scene_problems(scene_id, radar_masks, dataset))
    arrays, radars = {}, {}
    for radar, (timestamp_ns, masks) in radar_masks.items():
        arrays[f"{radar}/timestamp_ns"] = np.asarray(timestamp_ns, dtype=np.int64)
        arrays[f"{radar}/masks"] = np.ascontiguousarray(masks)
        radars[radar] = {"n_frames": int(masks.shape[0]), "shape": [int(n) for n in masks.shape]}
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    data = buffer.getvalue()
    path = Path(directory) / f"{scene_id}{SCENE_SUFFIX}"
    write_bytes_atomic(path, data)
    return {"file": path.name, "sha256": hashlib.sha256(data).hexdigest(), "radars": radars}


class MaskStore:
    """Automatic labels of a dataset's scenes, one ``.npz`` file per scene and a manifest.

    Open one with :meth:`create` (to write) or :meth:`open` (to read); the constructor is internal.

    Attributes
    ----------
    directory : pathlib.Path
        The store directory.
    manifest : dict
        The parsed ``manifest.json`` (layout in the module docstring); rewritten by :meth:`write_scene`.
    """

    def __init__(self, directory: Path, manifest: dict[str, Any], dataset_scene_ids: frozenset[str] | None) -> None:
        self.directory = directory
        self.manifest = manifest
        self._dataset_scene_ids = dataset_scene_ids

    def __repr__(self) -> str:
        return f"MaskStore({str(self.directory)!r}, scenes={len(self.manifest['scenes'])})"

    @property
    def manifest_path(self) -> Path:
        return self.directory / MANIFEST_FILENAME

    @property
    def parameters(self) -> dict[str, Any]:
        """The labelling parameters the store was made with."""
        return self.manifest["parameters"]

    @property
    def code_version(self) -> str:
        return self.manifest["code_version"]

    @property
    def dataset_fingerprint(self) -> str:
        return self.manifest["dataset"]["fingerprint"]

    def scene_ids(self) -> list[str]:
        """Scenes whose labels are stored, in the order they were written."""
        return list(self.manifest["scenes"])

    def scene_path(self, scene_id: str) -> Path:
        return self.directory / (scene_id + SCENE_SUFFIX)

    @classmethod
    def create(
        cls,
        out_dir: str | os.PathLike,
        dataset_root: DatasetIndex | str | os.PathLike,
        parameters: Mapping[str, Any],
        *,
        code_version: str | None = None,
    ) -> "MaskStore":
        """Start a store in ``out_dir``, or resume the one there.

        Parameters
        ----------
        out_dir
            The store directory: missing, empty, or a store of ours. Never inside ``dataset_root``.
        dataset_root
            The local dataset the labels are made from.
        parameters
            The labelling parameters (JSON-serialisable); recorded in the manifest.
        code_version
            Default :func:`zendar_baselines.code_version.code_version`.

        Returns
        -------
        MaskStore
            Resumed (its finished scenes kept) when ``out_dir`` holds a store of the same dataset,
            parameters and code version; started over (its own scene files removed) when the
            parameters or the code version differ.

        Raises
        ------
        ZendarError
            ``out_dir`` is inside the dataset, is not a directory, holds files but no manifest of
            ours, or holds a store of another format version or another dataset (nothing touched);
            the dataset or the parameters are invalid.
        """
        out = Path(out_dir)
        refuse_output_inside(out, datasets=(dataset_location(dataset_root),), what="auto-label store")
        dataset = dataset_index(dataset_root)
        fingerprint = dataset_fingerprint(dataset)
        parameters = _canonical_parameters(parameters)
        code_version = current_code_version() if code_version is None else code_version
        fresh = {
            "format": FORMAT_NAME,
            "format_version": FORMAT_VERSION,
            "code_version": code_version,
            "parameters": parameters,
            "dataset": {"root": _root_text(dataset_location(dataset_root)), "fingerprint": fingerprint},
            "scenes": {},
            "created_utc": _created_utc(),
        }
        store = cls(out, fresh, frozenset(dataset.scene_ids()))
        if out.exists() and not out.is_dir():
            raise MaskStoreError(f"auto-label store {out}: exists and is not a directory")
        manifest_path = out / MANIFEST_FILENAME
        if out.is_dir() and not manifest_path.exists():
            foreign = sorted(entry for entry in os.listdir(out) if owner_pid(out / entry) is None)
            if foreign:
                shown = ", ".join(foreign[:_FOREIGN_SHOWN]) + (", ..." if len(foreign) > _FOREIGN_SHOWN else "")
                raise MaskStoreError(
                    f"auto-label store {out}: holds someone else's files ({len(foreign)}: {shown}) and no "
                    f"{MANIFEST_FILENAME}; choose an empty or new directory (nothing was changed)"
                )
        if manifest_path.exists():
            recorded = _read_manifest(manifest_path)
            if isinstance(recorded, dict) and recorded.get("format") != FORMAT_NAME:
                raise MaskStoreError(
                    f"auto-label store {out}: holds someone else's files ({MANIFEST_FILENAME} of format "
                    f"{recorded.get('format')!r}); choose an empty or new directory (nothing was changed)"
                )
            _raise_problems(check_manifest(recorded, str(manifest_path)))
            if recorded["dataset"]["fingerprint"] != fingerprint:
                raise MaskStoreError(
                    f"auto-label store {out}: made from another dataset ({recorded['dataset']['root']}, "
                    f"dataset.json SHA-256 {recorded['dataset']['fingerprint'][:12]}...), not {dataset_location(dataset_root)} "
                    f"({fingerprint[:12]}...); choose another directory (nothing was changed)"
                )
            if recorded["parameters"] == parameters and recorded["code_version"] == code_version:
                recorded["dataset"]["root"] = fresh["dataset"]["root"]
                store.manifest = recorded
                remove_stale_temporaries(out)
                return store
            # Labels made with other parameters or code: start over, dropping only files our manifest lists.
            _make_directory(out)
            remove_stale_temporaries(out)
            store._write_manifest()
            for scene_id in recorded["scenes"]:
                store.scene_path(scene_id).unlink(missing_ok=True)
            return store
        _make_directory(out)
        remove_stale_temporaries(out)
        store._write_manifest()
        return store

    @classmethod
    def open(
        cls,
        out_dir: str | os.PathLike,
        dataset_root: DatasetIndex | str | os.PathLike | None = None,
        *,
        verify: bool = True,
        parameters: Mapping[str, Any] | None = None,
        code_version: str | None = None,
    ) -> "MaskStore":
        """Open a store to read it (or to add scenes).

        Parameters
        ----------
        out_dir
            The store directory.
        dataset_root
            When given, the store must have been made from this dataset (same ``dataset.json``).
        verify
            Check every scene file's SHA-256 and array shapes against the manifest (reads every
            file once; the arrays are not decompressed).
        parameters, code_version
            When given, the store must have been made with exactly these.

        Raises
        ------
        MaskStoreError
            Listing every problem found: no store there, a manifest of another format or version
            or unreadable, another dataset, other parameters or code version, a scene file missing,
            changed or not matching its manifest entry.
        """
        out = Path(out_dir)
        manifest_path = out / MANIFEST_FILENAME
        if not out.is_dir():
            raise MaskStoreError(f"auto-label store {out}: expected a directory, found {'a file' if out.exists() else 'nothing'}")
        manifest = _read_manifest(manifest_path)
        _raise_problems(check_manifest(manifest, str(manifest_path)))
        problems = []
        dataset_scene_ids = None
        if dataset_root is not None:
            dataset = dataset_index(dataset_root)
            dataset_scene_ids = frozenset(dataset.scene_ids())
            fingerprint = dataset_fingerprint(dataset)
            if manifest["dataset"]["fingerprint"] != fingerprint:
                problems.append(
                    f"{manifest_path}: dataset.fingerprint: made from another dataset ({manifest['dataset']['root']}, "
                    f"dataset.json SHA-256 {manifest['dataset']['fingerprint'][:12]}...), not {dataset_location(dataset_root)} ({fingerprint[:12]}...)"
                )
            unknown = [scene_id for scene_id in manifest["scenes"] if scene_id not in dataset_scene_ids]
            if unknown:
                problems.append(f"{manifest_path}: scenes: {unknown} are not scenes of {dataset_location(dataset_root)}")
        if parameters is not None and manifest["parameters"] != _canonical_parameters(parameters):
            problems.append(f"{manifest_path}: parameters: made with {manifest['parameters']}, expected {_canonical_parameters(parameters)}")
        if code_version is not None and manifest["code_version"] != code_version:
            problems.append(f"{manifest_path}: code_version: made by {manifest['code_version']!r}, expected {code_version!r}")
        store = cls(out, manifest, dataset_scene_ids)
        if verify:
            for scene_id in manifest["scenes"]:
                problems += store._scene_file_problems(scene_id)[0]
        _raise_problems(problems)
        return store

    def _scene_file_problems(self, scene_id: str) -> tuple[list[str], bytes | None]:
        path = self.scene_path(scene_id)
        try:
            data = path.read_bytes()
        except FileNotFoundError:
            return [f"{path}: expected the labels of scene {scene_id} listed in {MANIFEST_FILENAME}, found no file"], None
        except OSError as exc:
            return [f"{path}: cannot be read ({exc})"], None
        return _file_problems(path, data, self.manifest["scenes"][scene_id]), data

    def verify(self) -> None:
        """Check every scene file against the manifest; MaskStoreError listing every problem."""
        problems = []
        for scene_id in self.manifest["scenes"]:
            problems += self._scene_file_problems(scene_id)[0]
        _raise_problems(problems)

    def has_scene(self, scene_id: str, parameters: Mapping[str, Any], code_version: str) -> bool:
        """True when the store holds intact labels of ``scene_id`` made with ``parameters`` by ``code_version``.

        Intact: the file is present with its recorded SHA-256 and arrays, so a resumed run recomputes a
        scene whose file was damaged or removed.
        """
        if self.manifest["parameters"] != _canonical_parameters(parameters) or self.manifest["code_version"] != code_version:
            return False
        if scene_id not in self.manifest["scenes"]:
            return False
        return not self._scene_file_problems(scene_id)[0]

    def write_scene(self, scene_id: str, radar_masks: Mapping[str, tuple[np.ndarray, np.ndarray]]) -> None:
        """Store (or replace) one scene's masks, then record it in the manifest; both writes are atomic.

        Parameters
        ----------
        scene_id
            A scene of the store's dataset.
        radar_masks
            ``{radar: (timestamp_ns, masks)}``: int64 ``[N]`` strictly increasing cube times (ns) and
            uint8 ``[N, R, D]`` masks (values BACKGROUND, MOVING, UNCERTAIN), one per cube.

        Raises
        ------
        MaskStoreError
            Listing every problem with the scene id or the arrays; nothing is written then.
        """
        self.record_scene(scene_id, write_scene_file(self.directory, scene_id, radar_masks, self._dataset))

    def record_scene(self, scene_id: str, entry: dict[str, Any]) -> None:
        """Record a scene file written by :func:`write_scene_file` (on any host) in the manifest, atomically.

        Raises
        ------
        MaskStoreError
            When ``scene_id`` is not a scene of the store's dataset.
        """
        if self._dataset is not None and scene_id not in self._dataset[1]:
            raise MaskStoreError(f"scene {scene_id}: not a scene of the dataset {self._dataset[0]}")
        self.manifest["scenes"][scene_id] = entry
        self._write_manifest()

    @property
    def _dataset(self) -> tuple[str, frozenset[str]] | None:
        if self._dataset_scene_ids is None:
            return None
        return self.manifest["dataset"]["root"], self._dataset_scene_ids

    def scene(self, scene_id: str) -> RadarMasks:
        """One scene's masks, after checking the file's SHA-256 and arrays against the manifest.

        Returns
        -------
        dict
            ``{radar: (timestamp_ns int64 [N], masks uint8 [N, R, D])}``.

        Raises
        ------
        MaskStoreError
            Naming the file when it is missing, changed or does not hold what the manifest says,
            or naming the store when the scene is not in it.
        """
        if scene_id not in self.manifest["scenes"]:
            raise MaskStoreError(
                f"auto-label store {self.directory}: holds no labels of scene {scene_id!r} "
                f"(it holds {len(self.manifest['scenes'])} scenes: {self.scene_ids()})"
            )
        problems, data = self._scene_file_problems(scene_id)
        _raise_problems(problems)
        with np.load(io.BytesIO(data), allow_pickle=False) as archive:
            return {
                radar: (archive[f"{radar}/timestamp_ns"], archive[f"{radar}/masks"])
                for radar in self.manifest["scenes"][scene_id]["radars"]
            }

    def _write_manifest(self) -> None:
        write_text_atomic(self.manifest_path, json_text(self.manifest))


__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "MANIFEST_FILENAME",
    "MaskStore",
    "MaskStoreError",
    "check_manifest",
    "write_scene_file",
]
