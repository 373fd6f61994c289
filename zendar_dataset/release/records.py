"""Decoded release records as arrays: SAR frames, detections, lidar sweeps, poses, cubes.

Repeated sub-messages (detections, lidar points) are decoded column-wise
(:func:`zendar_dataset.release.columns.decode_repeated_columns`); everything
else goes through the strict generic decoder.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from zendar_dataset.release import messages as m
from zendar_dataset.release.messages import Kind
from zendar_dataset.release.columns import Columns, decode_repeated_columns, decode_repeated_field
from zendar_dataset.release.wire import WireError, count_unknown, decode

REAL_32U = 5
COMPLEX_32F = 1
REAL_32F = 3  # reserved in the schema, seen as an unknown enum value
EARTH_RADIUS_MIN_M = 6.3e6  # a position this far from the Earth's centre is ECEF, not a local frame


class MissingField(Exception):
    """A record lacks an optional field (in the SDK's definition) that its conversion needs.

    ``field`` names it (``"Image.cartesian"``); the importer skips such records and counts them.
    """

    def __init__(self, field: str, why: str) -> None:
        super().__init__(f"{field} absent ({why})")
        self.field = field
        self.why = why


def gps_seconds_to_ns(seconds: float) -> int:
    """GPS seconds (float64) to int64 nanoseconds: the double's exact value rounded to the nearest ns.

    Exact rational arithmetic, so nothing is rounded before the last step (``seconds * 1e9`` in
    float64 would already be off by up to 128 ns near 1.3e9 s); an exact tie rounds to even, as
    ``round(fractions.Fraction(seconds) * 10**9)``.
    """
    numerator, denominator = float(seconds).as_integer_ratio()
    quotient, remainder = divmod(numerator * 10**9, denominator)
    if 2 * remainder > denominator or (2 * remainder == denominator and quotient % 2):
        quotient += 1
    return quotient


def _vec(value: dict | None) -> np.ndarray:
    if value is None:
        return np.full(3, np.nan)
    return np.array([value["x"], value["y"], value["z"]], np.float64)


def _quat(value: dict | None) -> np.ndarray:
    if value is None:
        return np.full(4, np.nan)
    return np.array([value["w"], value["x"], value["y"], value["z"]], np.float64)


@dataclass
class SarFrame:
    """One SAR ``Image`` record.

    Attributes
    ----------
    timestamp_s : float
        GPS seconds at the middle of the aperture.
    position_ecef, attitude_wxyz : ndarray, (3,) / (4,), float64
        Vehicle pose (NaN when absent).
    frame_id : int or None
    serial : str or None
    origin_ecef, di_ecef, dj_ecef : ndarray, (3,), float64
        Image model: pixel (i, j) at origin + i·di + j·dj, ECEF metres.
    rows, cols : int
    pixel_type : int or None
        The ``type`` enum as written (unreliable, see :func:`sar_pixels`).
    data : memoryview
        The pixel buffer.
    """

    timestamp_s: float
    position_ecef: np.ndarray
    attitude_wxyz: np.ndarray
    frame_id: int | None
    serial: str | None
    origin_ecef: np.ndarray
    di_ecef: np.ndarray
    dj_ecef: np.ndarray
    rows: int
    cols: int
    pixel_type: int | None
    data: memoryview


def sar_frame(kind: Kind, record: dict) -> SarFrame:
    """A :class:`SarFrame` from a decoded ``Image`` of either generation.

    Raises :class:`MissingField` without ``cartesian`` (a ``oneof`` member, so optional) or, in
    2021, without ``meta`` (optional; it holds the timestamp).
    """
    if "cartesian" not in record:
        raise MissingField("Image.cartesian", "optional in the SDK (oneof image_model); it holds the image")
    if kind.generation == "2021" and "meta" not in record:
        raise MissingField("Image.meta", "optional in the 2021 SDK; it holds the timestamp")
    top = record["meta"] if kind.generation == "2021" else record
    cartesian = record["cartesian"]
    model, data = cartesian["model"], cartesian["data"]
    return SarFrame(
        timestamp_s=float(top.get("timestamp", np.nan)),
        position_ecef=_vec(top.get("position")),
        attitude_wxyz=_quat(top.get("attitude")),
        frame_id=top.get("frame_id"),
        serial=top.get("serial"),
        origin_ecef=_vec(model.get("origin")),
        di_ecef=_vec(model.get("di")),
        dj_ecef=_vec(model.get("dj")),
        rows=int(data["rows"]),
        cols=int(data["cols"]),
        pixel_type=data.get("type"),
        data=data.get("data", memoryview(b"")),
    )


def sar_frame_record(kind: Kind, buf: memoryview, start: int, end: int, unknown: dict[str, int] | None = None) -> SarFrame:
    """:func:`sar_frame` of one ``Image`` record (``unknown`` as :func:`~zendar_dataset.release.wire.decode`'s)."""
    return sar_frame(kind, decode(kind.message, buf, start, end, unknown))


def sar_flat(frame: SarFrame) -> tuple[np.ndarray, str]:
    """The pixel buffer as a flat ``[rows·cols]`` array of its element type, and ``"complex"`` or ``"magnitude"``.

    See :func:`sar_pixels` for how the element type is chosen; ValueError when the size fits neither.
    """
    count = frame.rows * frame.cols
    size = len(frame.data)
    if count == 0 or size % count or size // count not in (4, 8):
        raise ValueError(f"{size} bytes of pixel data do not hold rows×cols = {frame.rows}×{frame.cols} pixels of 4 or 8 bytes")
    if size // count == 8:
        return np.frombuffer(frame.data, "<c8"), "complex"
    return np.frombuffer(frame.data, "<f4" if frame.pixel_type == REAL_32F else "<u4"), "magnitude"


def sar_grid(frame: SarFrame, i_fastest: bool = True) -> tuple[np.ndarray, str]:
    """The image ``[rows, cols]`` in its recorded element type (``<u4``, ``<f4`` or ``<c8``), element
    [i, j] = pixel (i, j), and what it holds (``"complex"`` or ``"magnitude"``); see :func:`sar_pixels`.

    A view of the record's buffer (transposed when ``i_fastest``): nothing is copied or converted.
    """
    flat, holds = sar_flat(frame)
    return (flat.reshape(frame.cols, frame.rows).T if i_fastest else flat.reshape(frame.rows, frame.cols)), holds


def sar_pixels(frame: SarFrame, i_fastest: bool = True) -> tuple[np.ndarray, str]:
    """The image ``[rows, cols]`` complex64 with element [i, j] = pixel (i, j), and what it holds.

    The element size comes from ``len(data) / (rows·cols)`` (the ``type`` enum only breaks
    ties: absent, it reads as COMPLEX_32F although the data are uint32). 4 bytes: ``<u4``
    magnitude (``<f4`` when ``type`` says REAL_32F); 8 bytes: ``<c8`` complex.

    Parameters
    ----------
    i_fastest
        True: pixel (i, j) is flat element ``j·rows + i`` (the SDK viewer's reading);
        False: ``i·cols + j`` (row-major rows × cols).

    Returns
    -------
    image : ndarray, [rows, cols], complex64
        Magnitude images have zero imaginary part.
    holds : str
        ``"complex"`` or ``"magnitude"``.

    Raises
    ------
    ValueError
        When the buffer size is not 4 or 8 bytes per pixel.
    """
    grid, holds = sar_grid(frame, i_fastest)
    return grid.astype(np.complex64), holds


@dataclass
class Pose:
    """One tracklog ``Position``: GPS seconds, ECEF metres of the IMU, IMU(FRD)→ECEF quaternion wxyz."""

    timestamp_s: float
    position_ecef: np.ndarray
    attitude_wxyz: np.ndarray


def pose(record: dict) -> Pose:
    return Pose(float(record["timestamp"]), _vec(record.get("position")), _quat(record.get("attitude")))


def poses(
    buf: memoryview, offsets: np.ndarray, lengths: np.ndarray, unknown: dict[str, int] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every ``Position`` record of a stream, column-wise: ``[K]`` GPS seconds, ``[K, 3]`` ECEF metres,
    ``[K, 4]`` wxyz (NaN where absent); raises :class:`WireError` at the first record that does not decode."""
    raw = _columns(m.POSITION, buf, offsets, lengths, unknown)
    return raw["timestamp"], raw.block("position", "xyz"), raw.block("attitude", "wxyz")


@dataclass
class Detections:
    """One ``TrackerState``: the frame's time and id, and per-detection columns.

    ``columns`` maps ``range_m``, ``azimuth_rad``, ``elevation_rad``, ``range_velocity_mps``,
    ``magnitude``, ``snr``, ``rd_mean_snr`` to ``[P]`` float64 and ``position_ecef`` to ``[P, 3]``
    float64; NaN where the release has NaN or the field is absent.
    """

    timestamp_s: float
    frame_id: int | None
    serial: str | None
    columns: dict[str, np.ndarray]


# Our column -> the release's field name, per generation (fields 3 and 10 were renamed in 2021).
_POINT_COLUMNS = {
    generation: {
        "range_m": "range",
        "azimuth_rad": "azimuth",
        "elevation_rad": "elevation",
        "range_velocity_mps": "range_velocity",
        "magnitude": magnitude,
        "snr": snr,
        "rd_mean_snr": "rd_mean_snr",
    }
    for generation, magnitude, snr in (("2020", "amplitude", "confidence"), ("2021", "magnitude", "doa_snr"))
}


def _check_others(message, others: dict[int, list], repeated: int, unknown: dict[str, int] | None) -> None:
    for number, items in list(others.items()):
        spec = message.fields.get(number)
        if spec is None:
            if unknown is None:
                raise WireError(f"{message.name}: unknown field {number}", 0)
            for _ in items:
                count_unknown(unknown, message, number)
            del others[number]
            continue
        if number == repeated or any(wire != message.wire_type(number) for wire, _ in items):
            raise WireError(f"{message.name}.{spec.name} (field {number}): unexpected wire type", 0)
    missing = message.required - set(others) - {repeated}
    if missing:
        raise WireError(f"{message.name}: missing required field {sorted(missing)}", 0)


def _columns(
    element, buf: memoryview, offsets: np.ndarray, lengths: np.ndarray, unknown: dict[str, int] | None = None
) -> Columns:
    """The elements column-wise (:func:`_complete`)."""
    columns, slow = decode_repeated_columns(element, buf, offsets, lengths)
    return _complete(columns, slow, element, buf, offsets, lengths, unknown)


def _complete(
    columns: Columns, slow: list[int], element, buf: memoryview, offsets: np.ndarray, lengths: np.ndarray,
    unknown: dict[str, int] | None,
) -> Columns:
    """Decode the elements the compiled loop handed back with the generic decoder, in order (so the first that
    does not decode raises its :class:`WireError`, and unknown fields are counted)."""
    for index in slow:
        decoded = decode(element, buf, int(offsets[index]), int(offsets[index] + lengths[index]), unknown)
        for name, value in _flatten(decoded):
            if name in columns:  # every numeric field the conversions read is a column
                columns[name][index] = value
    return columns


def _flatten(decoded: dict, prefix: str = ""):
    for name, value in decoded.items():
        if isinstance(value, dict):
            yield from _flatten(value, f"{prefix}{name}.")
        elif isinstance(value, (int, float)):
            yield f"{prefix}{name}", value


def detections(kind: Kind, buf: memoryview, start: int, end: int, unknown: dict[str, int] | None = None) -> Detections:
    """A :class:`Detections` from one ``TrackerState`` record of either generation (strictly checked;
    ``unknown`` as :func:`~zendar_dataset.release.wire.decode`'s).

    Raises :class:`MissingField` for a 2021 record without ``meta`` (optional; it holds the timestamp).
    """
    element = kind.message.fields[2].type
    points = decode_repeated_field(element, 2, buf, start, end)
    others = points.others
    _check_others(kind.message, others, 2, unknown)
    head_message = m.METADATA if kind.generation == "2021" else m.TIME_RECORD
    if kind.generation == "2021" and 1 not in others:
        raise MissingField("TrackerState.meta", "optional in the 2021 SDK; it holds the timestamp")
    head = {}
    if 1 in others:
        offset, length = others[1][-1][1]
        head = decode(head_message, buf, offset, offset + length, unknown)
    if kind.generation == "2021":
        timestamp, frame_id, serial = head.get("timestamp", np.nan), head.get("frame_id"), head.get("serial")
    else:
        timestamp = head.get("common", np.nan)
        frame_id = others[3][-1][1] if 3 in others else None
        serial = None
        if 4 in others:
            offset, length = others[4][-1][1]
            serial = bytes(buf[offset : offset + length]).decode("utf-8", errors="replace")
    raw = _complete(points.columns, points.slow, element, buf, points.offsets, points.lengths, unknown)
    names = _POINT_COLUMNS["2021" if kind.generation == "2021" else "2020"]
    columns = {ours: raw[theirs] for ours, theirs in names.items()}
    columns["position_ecef"] = raw.block("position", "xyz")
    return Detections(float(timestamp), frame_id, serial, columns)


@dataclass
class LidarSweep:
    """One ``LidarPointsFrame``: GPS seconds and per-point ``[P, 3]`` positions and ``[P]`` intensity.

    ``position_local`` is None for the January-2021 draft layout, which has one position only.
    """

    timestamp_s: float
    position_ecef: np.ndarray
    position_local: np.ndarray | None
    intensity: np.ndarray


def lidar_sweep(kind: Kind, buf: memoryview, start: int, end: int, unknown: dict[str, int] | None = None) -> LidarSweep:
    """A :class:`LidarSweep` from one ``LidarPointsFrame`` of either point layout (``unknown`` as
    :func:`~zendar_dataset.release.wire.decode`'s)."""
    element = kind.message.fields[2].type
    points = decode_repeated_field(element, 2, buf, start, end)
    _check_others(kind.message, points.others, 2, unknown)
    offset, _ = points.others[1][-1][1]
    timestamp = float(np.frombuffer(buf, "<f8", 1, offset)[0])
    raw = _complete(points.columns, points.slow, element, buf, points.offsets, points.lengths, unknown)
    if kind.generation == "2021-01 draft":
        return LidarSweep(timestamp, raw.block("position", "xyz"), None, raw["intensity"])
    return LidarSweep(timestamp, raw.block("position_global", "xyz"), raw.block("position_local", "xyz"), raw["intensity"])


def looks_ecef(points: np.ndarray) -> bool:
    """Whether finite points sit at least 6300 km from the origin (ECEF rather than a sensor frame)."""
    finite = points[:1024][np.all(np.isfinite(points[:1024]), axis=1)]  # a sample decides: all points share a frame
    return bool(finite.size) and bool(np.median(np.linalg.norm(finite, axis=1)) > EARTH_RADIUS_MIN_M)


@dataclass
class RangeDopplerModel:
    """A ``RangeDopplerImageModel``: axes (start, delta, count), receivers ``[A, 3]`` and wavelength (m)."""

    num_rx: int
    range_axis: tuple[float, float, int]
    doppler_axis: tuple[float, float, int]
    rx_positions_m: np.ndarray
    wavelength_m: float


def rd_model(record: dict) -> RangeDopplerModel:
    def axis(value: dict) -> tuple[float, float, int]:
        return float(value["start"]), float(value["delta"]), int(value["count"])

    rx = np.array([_vec(v) for v in record.get("rx_positions", [])], np.float64).reshape(-1, 3)
    return RangeDopplerModel(
        int(record["num_rx"]), axis(record["range_axis_params"]), axis(record["doppler_axis_params"]), rx, float(record["wavelength"])
    )
