"""The SDK's message definitions, both generations, built in code as protobuf descriptors.

Field names, numbers, labels and types as the SDK declares them (nothing else is taken):

- 2020: ZendarInc/ZendarSDK ``protocol/data.proto`` at 5ef1144 (the schema of the 2020 release).
- 2021: the same repository's zendar-zenapi 0.1.2105261814 package (``usr/lib/zendar/{data,metadata,
  tracker,primitive,pose,lidar}.proto``), where ``Image`` and ``TrackerState`` are built around
  ``Metadata``.  The range-Doppler and camera messages exist only in the 2020 file; a 2021 recording
  uses them as they are there.

The protobuf runtime then serializes test recordings exactly as the SDK's writer did, independently
of the project's decoder (``tests/release/encoder.py`` stays for malformed bytes).
"""

from __future__ import annotations

import functools
import struct

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

F = descriptor_pb2.FieldDescriptorProto
REQ, OPT, REP = F.LABEL_REQUIRED, F.LABEL_OPTIONAL, F.LABEL_REPEATED
_SCALARS = {
    "double": F.TYPE_DOUBLE,
    "float": F.TYPE_FLOAT,
    "int32": F.TYPE_INT32,
    "uint32": F.TYPE_UINT32,
    "uint64": F.TYPE_UINT64,
    "bool": F.TYPE_BOOL,
    "string": F.TYPE_STRING,
    "bytes": F.TYPE_BYTES,
}

# message -> [(field name, number, label, type)]; a type that is not a scalar names a message, or an
# enum when it is listed in _ENUMS.  ("oneof", name, [fields]) declares a oneof.
_PRIMITIVES = {
    "Vec3d": [("x", 1, REQ, "double"), ("y", 2, REQ, "double"), ("z", 3, REQ, "double")],
    "Quaternion": [("w", 1, REQ, "double"), ("x", 2, REQ, "double"), ("y", 3, REQ, "double"), ("z", 4, REQ, "double")],
    "TimeRecord": [("common", 1, REQ, "double"), ("sensor", 2, OPT, "double")],
    "ImagePerformance": [("fps", 1, OPT, "double")],
    "ImageModelCartesian": [("origin", 1, OPT, "Vec3d"), ("di", 2, OPT, "Vec3d"), ("dj", 3, OPT, "Vec3d")],
    "ImageCartesian": [("model", 1, REQ, "ImageModelCartesian"), ("data", 2, REQ, "ImageDataCartesian")],
    "LinearSamplingParams": [("start", 1, REQ, "double"), ("delta", 2, REQ, "double"), ("count", 3, REQ, "int32")],
    "RangeDopplerImageModel": [
        ("num_rx", 1, REQ, "uint32"),
        ("range_axis_params", 2, REQ, "LinearSamplingParams"),
        ("doppler_axis_params", 3, REQ, "LinearSamplingParams"),
        ("rx_positions", 4, REP, "Vec3d"),
        ("wavelength", 5, REQ, "double"),
    ],
    "RangeDopplerFrame": [("timestamp", 1, REQ, "double"), ("data", 2, REQ, "bytes")],
    "Position": [
        ("timestamp", 1, REQ, "double"),
        ("attitude", 2, REQ, "Quaternion"),
        ("position", 3, REQ, "Vec3d"),
        ("update_id", 4, OPT, "uint64"),
        ("quality", 5, OPT, "PositionQuality"),
    ],
    "PositionQuality": [("satellite_count", 1, OPT, "int32"), ("gps_status", 2, OPT, "GpsFix"), ("ins_status", 3, OPT, "InsMode")],
    "CameraIndexRecord": [("timestamp", 1, REQ, "TimeRecord"), ("frame_index", 2, REQ, "uint64")],
    "LidarPointsFrame": [("timestamp", 1, REQ, "double"), ("point_cloud", 2, REP, "LidarPoint")],
    "LidarPoint": [
        ("timestamp", 1, REQ, "double"),
        ("position_global", 2, REQ, "Vec3d"),
        ("position_local", 3, REQ, "Vec3d"),
        ("intensity", 4, REQ, "uint32"),
    ],
}
_ENUMS = {
    "GpsFix": [("NO_FIX", 0), ("TIME_ONLY", 1), ("FIX_2D", 2), ("FIX_3D", 3)],
    "InsMode": [("NOT_TRACKING", 0), ("ALIGNING", 1), ("TRACKING", 2), ("LOSS_OF_GPS", 3)],
    "INSStatus.Mode": [("NOT_TRACKING", 0), ("ALIGNING", 1), ("TRACKING", 2), ("LOSS_OF_GPS", 3)],
    "ImageDataCartesian.Type": [("COMPLEX_32F", 1), ("REAL_32U", 5)],
}


def _point(names: tuple[str, str], rd_mean_snr: bool) -> list:
    fields = [
        ("timestamp", 1, REQ, "TimeRecord"),
        ("position", 2, REQ, "Vec3d"),
        (names[0], 3, OPT, "float"),
        ("azimuth_variance", 4, OPT, "float"),
        ("elevation_variance", 5, OPT, "float"),
        ("range", 6, OPT, "float"),
        ("range_velocity", 7, OPT, "float"),
        ("azimuth", 8, OPT, "float"),
        ("elevation", 9, OPT, "float"),
        (names[1], 10, OPT, "float"),
    ]
    return fields + ([("rd_mean_snr", 11, OPT, "float")] if rd_mean_snr else [])


def _image_data(type_label: int) -> list:
    return [
        ("type", 1, type_label, "ImageDataCartesian.Type"),
        ("rows", 2, REQ, "uint32"),
        ("cols", 3, REQ, "uint32"),
        ("data", 4, OPT, "bytes"),
    ]


SCHEMA_2020 = {
    **_PRIMITIVES,
    "Image": [
        ("timestamp", 1, REQ, "double"),
        ("attitude", 2, REQ, "Quaternion"),
        ("position", 3, REQ, "Vec3d"),
        ("frame_id", 4, OPT, "uint64"),
        ("performance", 5, OPT, "ImagePerformance"),
        ("oneof", "image_model", [("cartesian", 10, OPT, "ImageCartesian")]),
    ],
    "ImageDataCartesian": _image_data(OPT),  # optional in 5ef1144 (f0d4c9f)
    "TrackerState": [("timestamp", 1, REQ, "TimeRecord"), ("detection", 2, REP, "Point"), ("frame_id", 3, OPT, "uint64")],
    "Point": _point(("amplitude", "confidence"), rd_mean_snr=False),
}
SCHEMA_2021 = {
    **_PRIMITIVES,
    "Metadata": [
        ("timestamp", 1, OPT, "double"),
        ("attitude", 2, OPT, "Quaternion"),
        ("position", 3, OPT, "Vec3d"),
        ("frame_id", 4, OPT, "uint64"),
        ("serial", 5, OPT, "string"),
        ("max_range", 6, OPT, "double"),
    ],
    "Image": [
        ("meta", 1, OPT, "Metadata"),
        ("performance", 2, OPT, "ImagePerformance"),
        ("oneof", "image_model", [("cartesian", 10, OPT, "ImageCartesian")]),
    ],
    "ImageDataCartesian": _image_data(REQ),
    "TrackerState": [("meta", 1, OPT, "Metadata"), ("detection", 2, REP, "Point")],
    "Point": _point(("magnitude", "doa_snr"), rd_mean_snr=True),
    "INSStatus": [
        ("mode", 1, REQ, "INSStatus.Mode"),
        ("gps_has_fix", 2, REQ, "bool"),
        ("error_imu", 3, REQ, "bool"),
        ("error_magnetometer_or_pressure", 4, REQ, "bool"),
        ("error_gps", 5, REQ, "bool"),
    ],
    "PoseQuality": [
        ("position_uncertainty", 1, OPT, "Vec3d"),
        ("velocity_uncertainty", 2, OPT, "double"),
        ("gps_fix", 3, OPT, "GpsFix"),
        ("number_of_satellites", 4, OPT, "int32"),
        ("ins_status", 5, OPT, "INSStatus"),
        ("orientation_uncertainty", 6, OPT, "Vec3d"),
    ],
    "PoseRecord": [
        ("timestamp", 1, REQ, "TimeRecord"),
        ("position", 2, REQ, "Vec3d"),
        ("velocity", 3, OPT, "Vec3d"),
        ("acceleration", 4, OPT, "Vec3d"),
        ("orientation", 5, REQ, "Quaternion"),
        ("angular_velocity", 6, OPT, "Vec3d"),
        ("angular_acceleration", 7, OPT, "Vec3d"),
        ("pose_quality", 8, OPT, "PoseQuality"),
    ],
}


def _field(package: str, name: str, number: int, label: int, kind: str) -> F:
    field = F(name=name, number=number, label=label)
    if kind in _SCALARS:
        field.type = _SCALARS[kind]
    else:
        field.type = F.TYPE_ENUM if kind in _ENUMS else F.TYPE_MESSAGE
        field.type_name = f".{package}.{kind}"
    return field


def _file(package: str, schema: dict) -> descriptor_pb2.FileDescriptorProto:
    proto = descriptor_pb2.FileDescriptorProto(name=f"{package}.proto", package=package, syntax="proto2")
    for enum_name, values in _ENUMS.items():
        owner, _, short = enum_name.rpartition(".")
        if owner and owner not in schema:
            continue
        if not owner:
            enum = proto.enum_type.add(name=short)
            enum.value.extend(descriptor_pb2.EnumValueDescriptorProto(name=n, number=v) for n, v in values)
    for message_name, fields in schema.items():
        message = proto.message_type.add(name=message_name)
        for enum_name, values in _ENUMS.items():
            owner, _, short = enum_name.rpartition(".")
            if owner == message_name:
                enum = message.enum_type.add(name=short)
                enum.value.extend(descriptor_pb2.EnumValueDescriptorProto(name=n, number=v) for n, v in values)
        for spec in fields:
            if spec[0] == "oneof":
                index = len(message.oneof_decl)
                message.oneof_decl.add(name=spec[1])
                for member in spec[2]:
                    field = message.field.add()
                    field.CopyFrom(_field(package, *member))
                    field.oneof_index = index
            else:
                message.field.add().CopyFrom(_field(package, *spec))
    return proto


@functools.cache
def sdk(generation: str) -> dict[str, type]:
    """Message name -> generated class for the SDK's ``"2020"`` or ``"2021"`` definitions."""
    package = f"zendar_sdk_{generation}"
    pool = descriptor_pool.DescriptorPool()
    pool.Add(_file(package, SCHEMA_2020 if generation == "2020" else SCHEMA_2021))
    schema = SCHEMA_2020 if generation == "2020" else SCHEMA_2021
    return {name: message_factory.GetMessageClass(pool.FindMessageTypeByName(f"{package}.{name}")) for name in schema}


def write_recording(path, messages, header: bool = True) -> None:
    """A stream as the SDK's writer writes it: 8 zero bytes, then ``[u32 LE length][serialized message]``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as out:
        if header:
            out.write(bytes(8))
        for message in messages:
            payload = message.SerializeToString()
            out.write(struct.pack("<I", len(payload)) + payload)
