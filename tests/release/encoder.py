"""A minimal protobuf encoder for test fixtures, written from the release's wire-format fact sheet.

Independent of ``zendar_dataset.release`` (which only decodes): field numbers
and wire types are spelled out here again, one function per message.
"""

from __future__ import annotations

import gzip as gzip_module
import pathlib
import struct

import numpy as np


def varint(value: int) -> bytes:
    if value < 0:
        value += 1 << 64  # negative int32/int64: ten bytes, two's complement
    out = bytearray()
    while True:
        byte = value & 0x7F
        value >>= 7
        if value:
            out.append(byte | 0x80)
        else:
            out.append(byte)
            return bytes(out)


def key(number: int, wire: int) -> bytes:
    return varint(number << 3 | wire)


def f64(number: int, value: float) -> bytes:
    return key(number, 1) + struct.pack("<d", value)


def f32(number: int, value: float) -> bytes:
    return key(number, 5) + struct.pack("<f", value)


def uvar(number: int, value: int) -> bytes:
    return key(number, 0) + varint(value)


def ld(number: int, payload: bytes) -> bytes:
    return key(number, 2) + varint(len(payload)) + payload


def vec3(x: float, y: float, z: float) -> bytes:
    return f64(1, x) + f64(2, y) + f64(3, z)


def quaternion(wxyz) -> bytes:
    w, x, y, z = (float(v) for v in wxyz)
    return f64(1, w) + f64(2, x) + f64(3, y) + f64(4, z)


def time_record(common: float, sensor: float | None = None) -> bytes:
    return f64(1, common) + (f64(2, sensor) if sensor is not None else b"")


def image_payload(origin, di, dj, rows: int, cols: int, data: bytes, pixel_type: int | None) -> bytes:
    model = ld(1, vec3(*origin)) + ld(2, vec3(*di)) + ld(3, vec3(*dj))
    body = (uvar(1, pixel_type) if pixel_type is not None else b"") + uvar(2, rows) + uvar(3, cols) + ld(4, data)
    return ld(1, model) + ld(2, body)


def image_2020(timestamp, attitude_wxyz, position, frame_id, origin, di, dj, rows, cols, data, pixel_type=5) -> bytes:
    """Image, 2020 form: 1 timestamp double, 2 attitude, 3 position, 4 frame_id, 5 performance, 10 cartesian."""
    return (
        f64(1, timestamp)
        + ld(2, quaternion(attitude_wxyz))
        + ld(3, vec3(*position))
        + uvar(4, frame_id)
        + ld(5, f64(1, 10.0))
        + ld(10, image_payload(origin, di, dj, rows, cols, data, pixel_type))
    )


def metadata(timestamp, attitude_wxyz=None, position=None, frame_id=None, serial=None) -> bytes:
    out = f64(1, timestamp)
    if attitude_wxyz is not None:
        out += ld(2, quaternion(attitude_wxyz))
    if position is not None:
        out += ld(3, vec3(*position))
    if frame_id is not None:
        out += uvar(4, frame_id)
    if serial is not None:
        out += ld(5, serial.encode())
    return out


def image_2021(timestamp, attitude_wxyz, position, frame_id, origin, di, dj, rows, cols, data, pixel_type=1, serial=None) -> bytes:
    """Image, 2021 form: 1 meta (Metadata), 2 performance, 10 cartesian."""
    return (
        ld(1, metadata(timestamp, attitude_wxyz, position, frame_id, serial))
        + ld(2, f64(1, 10.0))
        + ld(10, image_payload(origin, di, dj, rows, cols, data, pixel_type))
    )


def point(timestamp, position, magnitude, range_m, range_velocity, azimuth, elevation, snr, rd_mean_snr=None) -> bytes:
    out = (
        ld(1, time_record(timestamp, sensor=12.5))
        + ld(2, vec3(*position))
        + f32(3, magnitude)
        + f32(4, 1e-4)
        + f32(5, 2e-4)
        + f32(6, range_m)
        + f32(7, range_velocity)
        + f32(8, azimuth)
        + f32(9, elevation)
        + f32(10, snr)
    )
    if rd_mean_snr is not None:
        out += f32(11, rd_mean_snr)
    return out


def tracker_state_2020(timestamp, points: list[bytes], frame_id: int) -> bytes:
    return ld(1, time_record(timestamp, sensor=3.0)) + b"".join(ld(2, p) for p in points) + uvar(3, frame_id)


def tracker_state_2021(timestamp, points: list[bytes], frame_id: int, attitude_wxyz, position) -> bytes:
    return ld(1, metadata(timestamp, attitude_wxyz, position, frame_id)) + b"".join(ld(2, p) for p in points)


def position_record(timestamp, attitude_wxyz, position, update_id: int, satellites: int = 9) -> bytes:
    quality = uvar(1, satellites) + uvar(2, 3) + uvar(3, 2)
    return f64(1, timestamp) + ld(2, quaternion(attitude_wxyz)) + ld(3, vec3(*position)) + uvar(4, update_id) + ld(5, quality)


def lidar_point(timestamp, position_global, position_local, intensity: int) -> bytes:
    return f64(1, timestamp) + ld(2, vec3(*position_global)) + ld(3, vec3(*position_local)) + uvar(4, intensity)


def lidar_point_draft(timestamp, position, intensity: int) -> bytes:
    return f64(1, timestamp) + ld(2, vec3(*position)) + uvar(3, intensity)


def lidar_frame(timestamp, points: list[bytes]) -> bytes:
    return f64(1, timestamp) + b"".join(ld(2, p) for p in points)


def sampling(start: float, delta: float, count: int) -> bytes:
    return f64(1, start) + f64(2, delta) + uvar(3, count)


def rd_model(num_rx: int, range_axis, doppler_axis, rx_positions, wavelength: float) -> bytes:
    out = uvar(1, num_rx) + ld(2, sampling(*range_axis)) + ld(3, sampling(*doppler_axis))
    out += b"".join(ld(4, vec3(*p)) for p in rx_positions)
    return out + f64(5, wavelength)


def rd_frame(timestamp: float, cube: np.ndarray) -> bytes:
    """RangeDopplerFrame: 1 timestamp, 2 data = complex64 little-endian, C order (range, doppler, rx)."""
    return f64(1, timestamp) + ld(2, np.ascontiguousarray(cube, "<c8").tobytes())


def camera_index(timestamp: float, frame_index: int) -> bytes:
    return ld(1, time_record(timestamp)) + uvar(2, frame_index)


def stream_bytes(records: list[bytes], header: bool) -> bytes:
    """``[8 zero bytes]`` then ``[u32 LE length][payload]`` per record."""
    out = bytearray(bytes(8) if header else b"")
    for payload in records:
        out += struct.pack("<I", len(payload)) + payload
    return bytes(out)


def write_stream(path: pathlib.Path, records: list[bytes], header: bool = True, gzip: bool = False) -> pathlib.Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    data = stream_bytes(records, header)
    path.write_bytes(gzip_module.compress(data) if gzip else data)
    return path


def chirp_response(timestamp: float, iq_words: np.ndarray, frame: int, chirp_index: int) -> bytes:
    """ChirpResponse (raw ADC): 1 timestamp, 2-5 rx0-rx3 IQ {3: packed fixed32 IQ}, 6 idx_frame, 8 chirp_index (int32)."""
    iq = ld(3, np.ascontiguousarray(iq_words, "<u4").tobytes())
    return ld(1, time_record(timestamp)) + b"".join(ld(n, iq) for n in (2, 3, 4, 5)) + uvar(6, frame) + uvar(7, 0) + uvar(8, chirp_index)


def time_index(common_time: float, file_offset: int) -> bytes:
    """TimeIndex (an index file's record): 1 common_time double, 2 file_offset uint64; no converted kind has this shape."""
    return f64(1, common_time) + uvar(2, file_offset)
