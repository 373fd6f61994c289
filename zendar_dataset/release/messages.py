"""The release's message definitions, both schema generations, as data.

Field numbers and types follow the wire-format fact sheet
(``docs/release.md`` summarises it): the 2020 repository schema (SAR
``Image``, ``TrackerState``, ``Position``, ``LidarPointsFrame``,
``RangeDopplerFrame`` + ``RangeDopplerImageModel``, ``CameraIndexRecord``),
the 2021 ``Metadata``-based forms of ``Image`` and ``TrackerState``, the
January-2021 draft lidar point layout, and the raw-acquisition messages
(recognised so that they can be reported, not converted).

Required fields are the SDK's ``required`` ones or fewer, never a field the SDK
declares ``optional`` or places in a ``oneof`` (``Image.cartesian``, the 2021
``meta``, ``ChirpResponse.rx0``): a record the SDK reads is never rejected here.
Where the SDK requires a field the importer can do without (``Image.attitude``
and ``position``, ``ImageDataCartesian.type`` in the 2021 packages), it is not
required here either.

A :class:`Kind` is one message type in one generation; sniffing a stream
(``release/stream.py``) keeps the kinds that decode its first records strictly.
"""

from __future__ import annotations

from dataclasses import dataclass

from zendar_dataset.errors import ZendarError
from zendar_dataset.release.wire import BYTES, DOUBLE, FLOAT, INT32, STRING, UINT, Field, Message


def _msg(name: str, required: tuple[int, ...] = (), **numbered: tuple) -> Message:
    fields = {}
    for key, spec in numbered.items():
        number = int(key[1:])
        fields[number] = Field(*spec)
    return Message(name, fields, frozenset(required))


VEC3D = _msg("Vec3d", (1, 2, 3), f1=("x", DOUBLE), f2=("y", DOUBLE), f3=("z", DOUBLE))
QUATERNION = _msg("Quaternion", (1, 2, 3, 4), f1=("w", DOUBLE), f2=("x", DOUBLE), f3=("y", DOUBLE), f4=("z", DOUBLE))
TIME_RECORD = _msg("TimeRecord", (1,), f1=("common", DOUBLE), f2=("sensor", DOUBLE))
METADATA = _msg(
    "Metadata",
    (),
    f1=("timestamp", DOUBLE),
    f2=("attitude", QUATERNION),
    f3=("position", VEC3D),
    f4=("frame_id", UINT),
    f5=("serial", STRING),
    f6=("max_range", DOUBLE),
)
IMAGE_PERFORMANCE = _msg("ImagePerformance", (), f1=("fps", DOUBLE))
IMAGE_MODEL = _msg("ImageModelCartesian", (), f1=("origin", VEC3D), f2=("di", VEC3D), f3=("dj", VEC3D))
IMAGE_DATA = _msg("ImageDataCartesian", (2, 3), f1=("type", UINT), f2=("rows", UINT), f3=("cols", UINT), f4=("data", BYTES))
IMAGE_CARTESIAN = _msg("ImageCartesian", (1, 2), f1=("model", IMAGE_MODEL), f2=("data", IMAGE_DATA))
IMAGE_2020 = _msg(
    "Image",
    (1,),
    f1=("timestamp", DOUBLE),
    f2=("attitude", QUATERNION),
    f3=("position", VEC3D),
    f4=("frame_id", UINT),
    f5=("performance", IMAGE_PERFORMANCE),
    f6=("serial", STRING),
    f10=("cartesian", IMAGE_CARTESIAN),
)
IMAGE_2021 = _msg("Image", (), f1=("meta", METADATA), f2=("performance", IMAGE_PERFORMANCE), f10=("cartesian", IMAGE_CARTESIAN))

def _point(generation: str) -> Message:
    """``Point``: fields 3 and 10 keep their numbers and types but were renamed in 2021 (amplitude ->
    magnitude, confidence -> doa_snr); field 11 exists from the 2021 packages (also in P21D's 2020-layout
    TrackerState), so both definitions accept it."""
    first, tenth = ("amplitude", "confidence") if generation == "2020" else ("magnitude", "doa_snr")
    return _msg(
        "Point",
        (1, 2),
        f1=("timestamp", TIME_RECORD),
        f2=("position", VEC3D),
        f3=(first, FLOAT),
        f4=("azimuth_variance", FLOAT),
        f5=("elevation_variance", FLOAT),
        f6=("range", FLOAT),
        f7=("range_velocity", FLOAT),
        f8=("azimuth", FLOAT),
        f9=("elevation", FLOAT),
        f10=(tenth, FLOAT),
        f11=("rd_mean_snr", FLOAT),
    )


POINT_2020 = _point("2020")
POINT_2021 = _point("2021")
TRACKER_STATE_2020 = _msg(
    "TrackerState",
    (1,),
    f1=("timestamp", TIME_RECORD),
    f2=("detection", POINT_2020, True),
    f3=("frame_id", UINT),
    f4=("serial", STRING),
)
TRACKER_STATE_2021 = _msg("TrackerState", (), f1=("meta", METADATA), f2=("detection", POINT_2021, True))

POSITION_QUALITY = _msg("PositionQuality", (), f1=("satellite_count", INT32), f2=("gps_status", UINT), f3=("ins_status", UINT))
POSITION = _msg(
    "Position",
    (1, 2, 3),
    f1=("timestamp", DOUBLE),
    f2=("attitude", QUATERNION),
    f3=("position", VEC3D),
    f4=("update_id", UINT),
    f5=("quality", POSITION_QUALITY),
)

LIDAR_POINT = _msg(
    "LidarPoint",
    (1, 2, 3, 4),
    f1=("timestamp", DOUBLE),
    f2=("position_global", VEC3D),
    f3=("position_local", VEC3D),
    f4=("intensity", UINT),
)
LIDAR_POINT_DRAFT = _msg("LidarPoint", (1, 2, 3), f1=("timestamp", DOUBLE), f2=("position", VEC3D), f3=("intensity", UINT))
LIDAR_FRAME = _msg("LidarPointsFrame", (1,), f1=("timestamp", DOUBLE), f2=("point_cloud", LIDAR_POINT, True))
LIDAR_FRAME_DRAFT = _msg("LidarPointsFrame", (1,), f1=("timestamp", DOUBLE), f2=("point_cloud", LIDAR_POINT_DRAFT, True))

SAMPLING = _msg("LinearSamplingParams", (1, 2, 3), f1=("start", DOUBLE), f2=("delta", DOUBLE), f3=("count", INT32))
RD_MODEL = _msg(
    "RangeDopplerImageModel",
    (1, 2, 3, 5),
    f1=("num_rx", UINT),
    f2=("range_axis_params", SAMPLING),
    f3=("doppler_axis_params", SAMPLING),
    f4=("rx_positions", VEC3D, True),
    f5=("wavelength", DOUBLE),
)
RD_FRAME = _msg("RangeDopplerFrame", (1, 2), f1=("timestamp", DOUBLE), f2=("data", BYTES))
CAMERA_INDEX = _msg("CameraIndexRecord", (1, 2), f1=("timestamp", TIME_RECORD), f2=("frame_index", UINT))

# Raw-acquisition messages: recognised for the summary, not converted.
LIDAR_RETURN = _msg("LidarReturn", (1, 2), f1=("distance", UINT), f2=("intensity", UINT))
LIDAR_FIRING = _msg(
    "LidarFiringBlock", (2, 3), f2=("block_identifier", UINT), f3=("rotational_position", UINT), f4=("laser_returns", LIDAR_RETURN, True)
)
LIDAR_DATA_FRAME = _msg(
    "LidarDataFrame",
    (3, 4),
    f1=("timestamp", TIME_RECORD),
    f2=("firings", LIDAR_FIRING, True),
    f3=("mode", UINT),
    f4=("sensor_type", UINT),
)
# IQ words are packed repeated (s)fixed32: one length-delimited field each. ChirpQuality's
# repeated CQ0-CQ2 sub-messages are kept as bytes (never converted).
IQ = _msg("IQ", (), f1=("I", BYTES), f2=("Q", BYTES), f3=("IQ", BYTES))
CHIRP_QUALITY = _msg("ChirpQuality", (), f1=("cq0", BYTES, True), f2=("cq1", BYTES, True), f3=("cq2", BYTES, True))
CHIRP_RESPONSE = _msg(
    "ChirpResponse",
    (1,),
    f1=("timestamp", TIME_RECORD),
    f2=("rx0", IQ),
    f3=("rx1", IQ),
    f4=("rx2", IQ),
    f5=("rx3", IQ),
    f6=("idx_frame", UINT),
    f7=("idx_frame_loop", UINT),
    f8=("chirp_index", INT32),
    f9=("chirp_quality", CHIRP_QUALITY),
)
INS_STATUS = _msg(
    "INSStatus",
    (1, 2, 3, 4, 5),
    f1=("mode", UINT),
    f2=("gps_has_fix", UINT),
    f3=("error_imu", UINT),
    f4=("error_magnetometer_or_pressure", UINT),
    f5=("error_gps", UINT),
)
POSE_QUALITY = _msg(
    "PoseQuality",
    (),
    f1=("position_uncertainty", VEC3D),
    f2=("velocity_uncertainty", DOUBLE),
    f3=("gps_fix", UINT),
    f4=("number_of_satellites", INT32),
    f5=("ins_status", INS_STATUS),
    f6=("orientation_uncertainty", VEC3D),
)
POSE_RECORD = _msg(
    "PoseRecord",
    (1, 2, 5),
    f1=("timestamp", TIME_RECORD),
    f2=("position", VEC3D),
    f3=("velocity", VEC3D),
    f4=("acceleration", VEC3D),
    f5=("orientation", QUATERNION),
    f6=("angular_velocity", VEC3D),
    f7=("angular_acceleration", VEC3D),
    f8=("pose_quality", POSE_QUALITY),
)


@dataclass(frozen=True)
class Kind:
    """One message type of one schema generation.

    Attributes
    ----------
    name : str
        The message name (``"Image"``, ``"TrackerState"``, ...).
    generation : str
        ``"2020"``, ``"2021"``, ``"2021-01 draft"`` (lidar point layout) or ``"raw"``.
    message : Message
        Its definition.
    converted : bool
        Whether ``import-release`` converts it (raw-acquisition packets are only reported).
    name_hints : tuple of str
        Substrings of file names users reported for it (used only to break ties between
        kinds that decode a stream equally well).
    expects : tuple of int
        Optional fields that hold what the importer converts (``Image.cartesian``): a kind whose
        sniffed records carry them is preferred over one whose records lack them (a ``Position``
        decodes as a 2020 ``Image`` without an image).
    """

    name: str
    generation: str
    message: Message
    converted: bool = True
    name_hints: tuple[str, ...] = ()
    expects: tuple[int, ...] = ()

    @property
    def label(self) -> str:
        return f"{self.name} ({self.generation})"


# Order matters only as the last tie-break: the 2020 release's kinds first.
KINDS: tuple[Kind, ...] = (
    Kind("Image", "2020", IMAGE_2020, name_hints=("_images",), expects=(10,)),
    Kind("Image", "2021", IMAGE_2021, name_hints=("_images",), expects=(1, 10)),
    Kind("TrackerState", "2020", TRACKER_STATE_2020, name_hints=("_points",)),
    Kind("TrackerState", "2021", TRACKER_STATE_2021, name_hints=("_points",), expects=(1,)),
    Kind("Position", "2020", POSITION, name_hints=("vn200", "tracklog")),
    Kind("LidarPointsFrame", "2020", LIDAR_FRAME, name_hints=("lidar",)),
    Kind("LidarPointsFrame", "2021-01 draft", LIDAR_FRAME_DRAFT, name_hints=("lidar",)),
    Kind("RangeDopplerFrame", "2020", RD_FRAME, name_hints=("_rd", "range_doppler")),
    Kind("RangeDopplerImageModel", "2020", RD_MODEL, name_hints=("model",)),
    Kind("CameraIndexRecord", "2020", CAMERA_INDEX, name_hints=("camera", "index")),
    Kind("LidarDataFrame", "raw", LIDAR_DATA_FRAME, converted=False, name_hints=("lidar",)),
    Kind("ChirpResponse", "raw", CHIRP_RESPONSE, converted=False, name_hints=("radar",)),
    Kind("PoseRecord", "raw", POSE_RECORD, converted=False, name_hints=("tracklog",)),
)
KIND_NAMES = tuple(dict.fromkeys(kind.name for kind in KINDS))


def kinds_named(name: str | None) -> tuple[Kind, ...]:
    """Every generation of message ``name`` (all kinds when None); ZendarError for an unknown name."""
    if name is None:
        return KINDS
    found = tuple(kind for kind in KINDS if kind.name == name)
    if not found:
        raise ZendarError(f"kind: expected one of {list(KIND_NAMES)}, found {name!r}")
    return found
