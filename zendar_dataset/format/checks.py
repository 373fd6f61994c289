"""Metadata checks of a scene store, shared by the reader (on open) and the validator.

Only attributes and array metadata (dtype, shape) are read here, never bulk
data, so opening a scene stays cheap even over object storage.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.format import checksums, stores
from zendar_dataset.format.calibration import CameraCalibration, Calibration, RadarCalibration
from zendar_dataset.format.schema import (
    CALIBRATION_ATTR,
    CALIBRATION_GROUP,
    ENU_ORIGIN_KEYS,
    EXTRA_SENSOR_GROUPS,
    LABELS,
    SAR_MAGNITUDE_DTYPES,
    SAR_MAGNITUDE_ONLY_ATTR,
    SENSOR_GROUPS,
    TIME_REFERENCE,
    TRACKLOG,
    ArraySpec,
    accepted_dtypes,
    expected_first_dim,
    optional_specs,
    stream_specs,
)


# Arrays stored one frame per chunk: (stream group, array name).
FRAME_CHUNKED = {("radar", "cube"), ("sar", "image"), ("camera", "image")}
# Claimed sizes beyond these are taken for corrupt metadata, not read: a scene of
# 20 Hz radar for 100 hours has 7.2 million chunks per stream.
MAX_CHUNKS = 2**24
MAX_ARRAY_BYTES = 2**40


@dataclass
class SceneMetadata:
    """What a metadata check learned about a scene (valid parts only)."""

    scene_id: str | None = None
    enu_origin: dict | None = None
    calibration: Calibration | None = None
    calibration_json: dict | None = None
    attrs: dict = field(default_factory=dict)
    streams: list[str] = field(default_factory=list)
    records_checksums: bool = False
    arrays: dict[str, Any] = field(default_factory=dict)  # path -> array whose metadata passed every check


def _shape_text(shape: tuple) -> str:
    return "[" + ", ".join(str(int(n)) for n in shape) + "]"


def get_node(root: Any, scene: str, path: str, problems: list[str]) -> Any | None:
    """The node at ``path``, or None when it is absent or its metadata is unreadable (a problem noted)."""
    try:
        return stores.get_node(root, path)
    except stores.MetadataError as exc:
        problems.append(f"{scene}: {exc}")
        return None


def check_array(
    root: Any,
    scene: str,
    stream: str,
    spec: ArraySpec,
    n_elements: int | None,
    problems: list[str],
    checksummed: bool = False,
) -> Any | None:
    """Check one array's presence, dtype, shape, chunking and checksum attribute.

    Returns the array when all are right (its data can then be read safely), else None.
    """
    path = f"{stream}/{spec.name}"
    count = len(problems)
    node = get_node(root, scene, path, problems)
    if len(problems) > count:
        return None
    if node is None or not stores.is_array(node):
        found = "a group" if node is not None else "nothing"
        problems.append(f"{scene}: {path}: expected an array {spec.describe()}, found {found}")
        return None
    dtype = np.dtype(node.dtype)
    ok = True
    accepted = accepted_dtypes(stream, spec)
    if dtype not in accepted:
        others = f" (or {', '.join(d.name for d in accepted[1:])} for a magnitude-only image)" if len(accepted) > 1 else ""
        problems.append(f"{scene}: {path}: expected dtype {spec.dtype.name}{others}, found {dtype.name}")
        ok = False
    shape = tuple(node.shape)
    if len(shape) != spec.ndim:
        problems.append(f"{scene}: {path}: expected shape {spec.describe()}, found {_shape_text(shape)}")
        return None
    for axis, (want, have) in enumerate(zip(spec.shape, shape)):
        if isinstance(want, int) and want != have:
            problems.append(f"{scene}: {path}: expected size {want} on axis {axis} ({spec.describe()}), found {_shape_text(shape)}")
            ok = False
    first = expected_first_dim(spec, n_elements) if n_elements is not None else None
    if first is not None and shape[0] != first:
        problems.append(
            f"{scene}: {path}: expected {first} rows ({spec.describe()} with N={n_elements} timestamps), "
            f"found {_shape_text(shape)}"
        )
        ok = False
    return node if ok and _check_storage(node, scene, stream, spec, problems, checksummed) else None


def _check_storage(node: Any, scene: str, stream: str, spec: ArraySpec, problems: list[str], checksummed: bool) -> bool:
    """Chunking and checksum attribute of an array whose dtype and shape are right."""
    path = f"{stream}/{spec.name}"
    shape = tuple(int(n) for n in node.shape)
    chunks = stores.chunk_shape(node) or shape
    n_chunks = checksums.chunk_count(shape, chunks)
    n_bytes = int(np.prod(shape, dtype=object)) * np.dtype(node.dtype).itemsize
    if n_chunks > MAX_CHUNKS or n_bytes > MAX_ARRAY_BYTES:
        problems.append(
            f"{scene}: {path}: expected a plausible size (at most {MAX_CHUNKS} chunks and {MAX_ARRAY_BYTES} bytes), "
            f"found shape {_shape_text(shape)} in {n_chunks} chunks ({n_bytes} bytes); the metadata is likely corrupt"
        )
        return False
    ok = True
    if (stream.split("/", 1)[0], spec.name) in FRAME_CHUNKED and shape and chunks != (1, *shape[1:]):
        problems.append(f"{scene}: {path}: expected one chunk per frame {[1, *shape[1:]]}, found chunks {list(chunks)}")
        ok = False
    if checksummed:
        try:
            checksums.decode(stores.read_attrs(node).get(checksums.ARRAY_ATTR), n_chunks)
        except ValueError as exc:
            problems.append(f"{scene}: {path}: attribute {checksums.ARRAY_ATTR}: {exc}")
            ok = False
    return ok


def check_stream(root: Any, scene: str, stream: str, problems: list[str], checksummed: bool = False) -> dict[str, Any]:
    """Check every array of one stream; returns the arrays that passed, by name."""
    specs = stream_specs(stream)
    timestamps = check_array(root, scene, stream, specs[0], None, problems, checksummed)
    n = int(timestamps.shape[0]) if timestamps is not None else None
    arrays = {specs[0].name: timestamps} if timestamps is not None else {}
    for spec in specs[1:]:
        node = check_array(root, scene, stream, spec, n, problems, checksummed)
        if node is not None:
            arrays[spec.name] = node
    for spec in optional_specs(stream):
        # An optional field with unreadable metadata is one problem (noted here), not a missing array.
        if get_node(root, scene, f"{stream}/{spec.name}", problems) is not None:
            node = check_array(root, scene, stream, spec, n, problems, checksummed)
            if node is not None:
                arrays[spec.name] = node
    return arrays


def _check_attrs(root: Any, scene: str, expected_scene_id: str | None, meta: SceneMetadata, problems: list[str]) -> None:
    attrs = stores.read_attrs(root)
    meta.attrs = attrs
    scene_id = attrs.get("scene_id")
    if not isinstance(scene_id, str) or not scene_id:
        problems.append(f"{scene}: /: expected attribute scene_id (a string), found {scene_id!r}")
    elif expected_scene_id is not None and scene_id != expected_scene_id:
        problems.append(f"{scene}: /: expected attribute scene_id {expected_scene_id!r} (dataset.json), found {scene_id!r}")
    else:
        meta.scene_id = scene_id
    reference = attrs.get("time_reference")
    if reference != TIME_REFERENCE:
        problems.append(f"{scene}: /: expected attribute time_reference {TIME_REFERENCE!r}, found {reference!r}")
    origin = attrs.get("enu_origin")
    if not isinstance(origin, dict) or set(origin) != set(ENU_ORIGIN_KEYS):
        found = sorted(origin) if isinstance(origin, dict) else repr(origin)
        problems.append(f"{scene}: /: expected attribute enu_origin with keys {list(ENU_ORIGIN_KEYS)}, found {found}")
    elif not all(
        isinstance(origin[k], (int, float)) and not isinstance(origin[k], bool) and np.isfinite(origin[k])
        for k in ENU_ORIGIN_KEYS
    ):
        problems.append(f"{scene}: /: expected attribute enu_origin with finite numeric values, found {origin}")
    else:
        meta.enu_origin = {k: float(origin[k]) for k in ENU_ORIGIN_KEYS}
    algorithm = attrs.get(checksums.ROOT_ATTR)
    if algorithm is not None and algorithm != checksums.ALGORITHM:
        problems.append(
            f"{scene}: /: expected attribute {checksums.ROOT_ATTR} {checksums.ALGORITHM!r} or none, found {algorithm!r}"
        )
    meta.records_checksums = algorithm == checksums.ALGORITHM


def _check_calibration(root: Any, scene: str, meta: SceneMetadata, problems: list[str]) -> None:
    count = len(problems)
    group = get_node(root, scene, CALIBRATION_GROUP, problems)
    if len(problems) > count:
        return
    if group is None or not stores.is_group(group):
        problems.append(f"{scene}: {CALIBRATION_GROUP}: expected a group with attribute {CALIBRATION_ATTR!r}, found nothing")
        return
    value = stores.read_attrs(group).get(CALIBRATION_ATTR)
    if value is None:
        problems.append(f"{scene}: {CALIBRATION_GROUP}: expected attribute {CALIBRATION_ATTR!r}, found nothing")
        return
    try:
        meta.calibration = Calibration.from_json(value)
        meta.calibration_json = value if isinstance(value, dict) else meta.calibration.to_json()
    except ZendarFormatError as exc:
        problems.extend(f"{scene}: {CALIBRATION_GROUP}: {p}" for p in exc.problems)


def _check_sensor_calibration(meta: SceneMetadata, scene: str, stream: str, arrays: dict, problems: list[str]) -> None:
    if meta.calibration is None:
        return
    group, sensor = stream.split("/", 1)
    entry = meta.calibration.sensors.get(sensor)
    kind = {"radar": RadarCalibration, "sar": RadarCalibration, "camera": CameraCalibration}.get(group)
    if entry is None:
        problems.append(f"{scene}: {CALIBRATION_GROUP}: expected an entry for sensor {sensor!r} ({stream}), found none")
        return
    if kind is not None and not isinstance(entry, kind):
        problems.append(
            f"{scene}: {CALIBRATION_GROUP}: expected {kind.__name__} fields for sensor {sensor!r} ({stream}), "
            f"found {type(entry).__name__}"
        )
        return
    if group == "radar" and "cube" in arrays:
        antennas = entry.rx_positions_m.shape[0]
        if arrays["cube"].shape[3] != antennas:
            problems.append(
                f"{scene}: {stream}/cube: expected A={antennas} antennas (rx_positions_m of {sensor!r}), "
                f"found {_shape_text(arrays['cube'].shape)}"
            )
    if group == "camera" and "image" in arrays:
        height, width = arrays["image"].shape[1:3]
        if (height, width) != (entry.height, entry.width):
            problems.append(
                f"{scene}: {stream}/image: expected [C, {entry.height}, {entry.width}, 3] (calibration height, width), "
                f"found {_shape_text(arrays['image'].shape)}"
            )


def _check_sar_layout(root: Any, scene: str, stream: str, arrays: dict, problems: list[str]) -> None:
    """``magnitude_only`` is a bool, and true wherever ``image`` holds real magnitudes (docs/format.md).

    A complex64 image with ``magnitude_only`` true is the layout of stores written before magnitude
    images existed (the magnitude in the real part): still valid.
    """
    group = get_node(root, scene, stream, problems)
    if group is None:
        return
    value = stores.read_attrs(group).get(SAR_MAGNITUDE_ONLY_ATTR)
    if value is not None and not isinstance(value, bool):
        problems.append(f"{scene}: {stream}: expected attribute {SAR_MAGNITUDE_ONLY_ATTR} true or false, found {value!r}")
        return
    image = arrays.get("image")
    if image is not None and np.dtype(image.dtype) in SAR_MAGNITUDE_DTYPES and value is not True:
        problems.append(
            f"{scene}: {stream}/image: expected attribute {SAR_MAGNITUDE_ONLY_ATTR} true on {stream} for an image of "
            f"{np.dtype(image.dtype).name} magnitudes, found " + ("none" if value is None else repr(value))
        )


def check_scene_metadata(root: Any, scene: str, expected_scene_id: str | None = None) -> tuple[SceneMetadata, list[str]]:
    """Check a scene's attributes, calibration and every array's dtype and shape.

    Parameters
    ----------
    root
        The store's root group.
    scene
        How to name the scene in messages (its id or location).
    expected_scene_id
        The id ``dataset.json`` gives it, when known.

    Returns
    -------
    (SceneMetadata, list of str)
        What was learned, and every violation found.
    """
    meta = SceneMetadata()
    problems: list[str] = []
    _check_attrs(root, scene, expected_scene_id, meta, problems)
    _check_calibration(root, scene, meta, problems)
    for group in SENSOR_GROUPS + EXTRA_SENSOR_GROUPS:
        node = get_node(root, scene, group, problems)
        if node is None:
            continue
        if not stores.is_group(node):
            problems.append(f"{scene}: {group}: expected a group of sensors, found an array")
            continue
        for sensor in stores.member_names(node):
            stream = f"{group}/{sensor}"
            arrays = check_stream(root, scene, stream, problems, meta.records_checksums)
            meta.arrays.update({f"{stream}/{name}": node for name, node in arrays.items()})
            _check_sensor_calibration(meta, scene, stream, arrays, problems)
            if group == "sar":
                _check_sar_layout(root, scene, stream, arrays, problems)
            meta.streams.append(stream)
    for stream in (TRACKLOG, LABELS):
        if get_node(root, scene, stream, problems) is not None:
            arrays = check_stream(root, scene, stream, problems, meta.records_checksums)
            meta.arrays.update({f"{stream}/{name}": node for name, node in arrays.items()})
            meta.streams.append(stream)
    if TRACKLOG in meta.streams and meta.calibration is not None and "imu" not in meta.calibration.sensors:
        problems.append(f"{scene}: {CALIBRATION_GROUP}: expected an entry for sensor 'imu' (tracklog), found none")
    return meta, problems
