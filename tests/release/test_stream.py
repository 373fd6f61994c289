"""The stream reader: framing, kinds, schema generations, truncation, NaN, large records."""

from __future__ import annotations

import gzip
import zlib
import math
import struct
from fractions import Fraction

import numpy as np
import pytest

from tests.release import encoder as enc
from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.release import ReleaseStream, iter_messages
from zendar_dataset.release import messages as m
from zendar_dataset.release.records import gps_seconds_to_ns, sar_frame, sar_pixels
from zendar_dataset.release.wire import WireError, decode

ATT = (0.5, -0.5, 0.5, -0.5)
POS = (-2_706_000.25, -4_261_000.5, 3_885_000.75)


def _image_2020(k: int, data: bytes = bytes(24 * 4), rows: int = 4, cols: int = 6, pixel_type: int | None = 5) -> bytes:
    return enc.image_2020(1.26e9 + k / 10, ATT, POS, k, (1.0, 2.0, 3.0), (0.04, 0, 0), (0, 0.04, 0), rows, cols, data, pixel_type)


def _image_2021(k: int) -> bytes:
    return enc.image_2021(1.26e9 + k / 10, ATT, POS, k, (1.0, 2.0, 3.0), (0.04, 0, 0), (0, 0.04, 0), 4, 6, bytes(24 * 8))


@pytest.mark.parametrize("header", [True, False])
@pytest.mark.parametrize("compress", [False, True])
def test_framing_is_detected_from_the_bytes_not_the_name(tmp_path, header, compress):
    # Names lie on purpose: a headerless file named like a data product and vice versa.
    name = "1739000J1Q_images.pbs" if not header else "stream.pbs"
    path = enc.write_stream(tmp_path / name, [_image_2020(k) for k in range(3)], header=header, gzip=compress)
    with ReleaseStream(path) as stream:
        assert stream.framing.header_bytes == (8 if header else 0)
        assert stream.framing.gzip is compress
        assert stream.kind.label == "Image (2020)"
        records = list(stream)
    assert [r["frame_id"] for r in records] == [0, 1, 2]
    assert records[2]["timestamp"] == 1.26e9 + 0.2


def test_zero_length_records_are_empty_messages_not_framing_errors(tmp_path):
    records = [_image_2020(0), b"", _image_2020(1)]
    path = enc.write_stream(tmp_path / "x.pbs", records, header=False)
    with ReleaseStream(path) as stream:
        assert stream.framing.header_bytes == 0
        assert [r["frame_id"] for r in stream] == [0, 1]
        assert stream.empty_records == 1
        # Read again (the import's probes read a stream more than once): still one empty record.
        assert len(list(stream.records())) == 2 and len(stream.spans()[0]) == 2
        assert stream.empty_records == 1


def test_headerless_file_starting_with_two_empty_records_is_read_as_header(tmp_path):
    # The fact sheet's rule: a zero 8-byte header and two empty records are the same bytes.
    path = enc.write_stream(tmp_path / "x.pbs", [b"", b"", _image_2020(0)], header=False)
    with ReleaseStream(path) as stream:
        assert stream.framing.header_bytes == 8
        assert "bytes 0-7 are zero" in stream.framing.reason
        assert len(list(stream)) == 1


def test_truncated_tail_names_offset_expected_and_available_bytes(tmp_path):
    data = enc.stream_bytes([_image_2020(k) for k in range(3)], header=True)
    path = tmp_path / "x_images.pbs"
    path.write_bytes(data[:-10])
    last = 8 + 2 * (4 + len(_image_2020(0)))
    size = len(_image_2020(2))
    with pytest.raises(ZendarFormatError) as info:
        ReleaseStream(path)
    message = str(info.value)
    assert f"byte offset {last}" in message and f"declares {size} bytes, only {size - 10} are available" in message
    assert "\n" not in message
    with ReleaseStream(path, skip_corrupt=True) as stream:
        assert len(list(stream)) == 2
        assert [(loss.offset, loss.size_bytes) for loss in stream.losses] == [(last, 4 + size - 10)]


def test_corrupt_length_in_the_middle_is_skipped_and_reading_resumes(tmp_path):
    records = [_image_2020(k) for k in range(4)]
    data = bytearray(enc.stream_bytes(records, header=True))
    second = 8 + 4 + len(records[0])
    data[second : second + 4] = struct.pack("<I", 0xFFFF_FFF0)  # a garbage length
    path = tmp_path / "x.pbs"
    path.write_bytes(bytes(data))
    with pytest.raises(ZendarFormatError, match=f"byte offset {second}"):
        ReleaseStream(path)
    with ReleaseStream(path, skip_corrupt=True) as stream:
        assert [r["frame_id"] for r in stream] == [0, 2, 3]
        assert sum(loss.size_bytes for loss in stream.losses) == 4 + len(records[1])


def test_truncated_gzip_is_reported_not_crashed(tmp_path):
    rng = np.random.default_rng(1)  # incompressible pixels, so two thirds of the file hold whole records
    raw = gzip.compress(enc.stream_bytes([_image_2020(k, rng.bytes(96)) for k in range(5)], header=False))
    path = tmp_path / "stream.pbs.gz"
    path.write_bytes(raw[: len(raw) * 2 // 3])
    with pytest.raises(ZendarFormatError, match="gzip stream ends early"):
        ReleaseStream(path)
    with ReleaseStream(path, skip_corrupt=True) as stream:
        assert 1 <= len(list(stream)) < 5
        assert stream.losses


def test_gzip_truncated_on_a_record_boundary_is_reported(tmp_path):
    # A recorder killed after a flush: the decompressed bytes hold whole records only.
    records = [_image_2020(k) for k in range(4)]
    whole = enc.stream_bytes(records, header=False)
    first_two = enc.stream_bytes(records[:2], header=False)
    compressor = zlib.compressobj(9, zlib.DEFLATED, 31)  # gzip container
    truncated = compressor.compress(first_two) + compressor.flush(zlib.Z_SYNC_FLUSH)
    assert len(truncated) < len(gzip.compress(whole))
    path = tmp_path / "stream.pbs"
    path.write_bytes(truncated)  # no gzip trailer: the compressed stream stops after the two records
    with pytest.raises(ZendarFormatError, match="gzip stream ends early"):
        ReleaseStream(path)
    with ReleaseStream(path, skip_corrupt=True) as stream:
        assert len(list(stream)) == 2
        assert stream.losses


def test_the_2020_2021_image_trap_is_caught(tmp_path):
    # Decoding either generation with the other's definition must fail, not parse silently.
    r2020, r2021 = memoryview(_image_2020(0)), memoryview(_image_2021(0))
    with pytest.raises(WireError):
        decode(m.IMAGE_2021, r2020)
    with pytest.raises(WireError):
        decode(m.IMAGE_2020, r2021)
    # A 2021 stream under a 2020-looking name is still read as 2021, timestamp from meta.
    path = enc.write_stream(tmp_path / "1739000J1Q_images.pbs", [_image_2021(k) for k in range(2)])
    with ReleaseStream(path, kind="Image") as stream:
        assert stream.kind.generation == "2021"
        frames = [sar_frame(stream.kind, r) for r in stream]
    assert frames[1].timestamp_s == 1.26e9 + 0.1 and frames[1].frame_id == 1
    np.testing.assert_array_equal(frames[0].position_ecef, POS)


def test_the_2020_2021_tracker_state_trap_is_caught(tmp_path):
    p = enc.point(1.26e9, POS, 5.0, 10.0, 1.0, 0.1, 0.0, 7.0)
    with pytest.raises(WireError):  # 2021 meta (attitude at field 2) is not a 2020 TimeRecord
        decode(m.TRACKER_STATE_2020, memoryview(enc.tracker_state_2021(1.26e9, [p], 4, ATT, POS)))
    with pytest.raises(WireError):  # 2020 frame_id (field 3) does not exist in 2021
        decode(m.TRACKER_STATE_2021, memoryview(enc.tracker_state_2020(1.26e9, [p], 4)))
    path = enc.write_stream(tmp_path / "a_points.pbs", [enc.tracker_state_2021(1.26e9, [p], 4, ATT, POS)])
    with ReleaseStream(path) as stream:
        assert stream.kind.label == "TrackerState (2021)"


def test_sniffs_every_kind_without_a_helpful_name(tmp_path):
    cube = np.zeros((4, 2, 2), np.complex64)
    lp = enc.lidar_point(1.26e9, POS, (1.0, 2.0, 3.0), 7)
    cases = {
        "Image (2020)": _image_2020(0),
        "Image (2021)": _image_2021(0),
        "TrackerState (2020)": enc.tracker_state_2020(1.26e9, [enc.point(1.26e9, POS, 1, 2, 3, 4, 5, 6)], 1),
        "Position (2020)": enc.position_record(1.26e9, ATT, POS, 3),
        "LidarPointsFrame (2020)": enc.lidar_frame(1.26e9, [lp, lp]),
        "LidarPointsFrame (2021-01 draft)": enc.lidar_frame(1.26e9, [enc.lidar_point_draft(1.26e9, POS, 9)] * 2),
        "RangeDopplerFrame (2020)": enc.rd_frame(1.26e9, cube + 1),
        "RangeDopplerImageModel (2020)": enc.rd_model(2, (0, 0.2, 4), (-0.1, 0.1, 2), [(0, 0, 0)], 0.0039),
        "CameraIndexRecord (2020)": enc.camera_index(1.26e9, 5),
    }
    for label, record in cases.items():
        path = enc.write_stream(tmp_path / "data.pbs", [record, record])
        with ReleaseStream(path) as stream:
            assert stream.kind.label == label, (label, stream.notes)


def test_nan_fields_come_through(tmp_path):
    nan = float("nan")
    path = enc.write_stream(tmp_path / "vn200.pbs", [enc.position_record(nan, ATT, (nan, 1.0, 2.0), 1)])
    (record,) = list(iter_messages(path))
    assert math.isnan(record["timestamp"]) and math.isnan(record["position"]["x"])


def test_negative_int32_ten_byte_varint(tmp_path):
    record = enc.rd_model(2, (0, 0.2, -3), (-0.1, 0.1, 2), [], 0.0039)
    (decoded,) = list(iter_messages(enc.write_stream(tmp_path / "m.pbs", [record]), kind="RangeDopplerImageModel"))
    assert decoded["range_axis_params"]["count"] == -3


def test_record_over_4_mib(tmp_path):
    cube = (np.arange(520 * 256 * 4, dtype=np.float32) * (1 + 1j)).astype(np.complex64).reshape(520, 256, 4)
    record = enc.rd_frame(1.26e9, cube)
    assert len(record) > 4 * 2**20
    path = enc.write_stream(tmp_path / "left_rd.pbs", [record, record])
    records = list(iter_messages(path, kind="RangeDopplerFrame"))
    assert len(records) == 2
    np.testing.assert_array_equal(np.frombuffer(records[1]["data"], "<c8").reshape(cube.shape), cube)


def test_pixel_order_and_dtype_follow_the_buffer_not_the_type_enum():
    rows, cols = 3, 5
    image = np.arange(rows * cols, dtype="<u4").reshape(rows, cols)  # value = i*cols + j
    flat_i_fastest = image.T.tobytes()  # element j*rows + i
    for pixel_type in (None, 1, 5):  # absent or mislabelled COMPLEX_32F: size says 4 bytes -> uint32
        record = memoryview(_image_2020(0, flat_i_fastest, rows, cols, pixel_type))
        frame = sar_frame(m.KINDS[0], decode(m.IMAGE_2020, record))
        pixels, holds = sar_pixels(frame)
        assert holds == "magnitude"
        np.testing.assert_array_equal(pixels.real, image)
        assert not pixels.imag.any()


@pytest.mark.parametrize(
    "seconds",
    [1_264_000_000.123456789, 1.3e9 + 0.5e-9, 0.1, 1_600_000_000.999999999, 1_264_000_000 + 1 / 1024, 1_264_000_000 + 3 / 1024],
)
def test_gps_seconds_to_ns_rounds_the_exact_double_to_the_nearest_ns(seconds):
    exact = Fraction(seconds) * 10**9
    assert gps_seconds_to_ns(seconds) == round(exact)  # exact; a tie (k/1024 s is x.5 ns) goes to even
    assert abs(Fraction(gps_seconds_to_ns(seconds)) - exact) <= Fraction(1, 2)


def test_gps_seconds_to_ns_is_not_float_arithmetic():
    seconds = 1_264_000_000.123456789
    assert gps_seconds_to_ns(seconds) - round(seconds * 1e9) != 0  # float64 product is a multiple of 256 ns here


def test_lidar_columns_match_the_encoded_values_across_layouts(tmp_path):
    # Intensities of one and two varint bytes, uniform and uneven spacing, and one point whose
    # local position is left out (a layout of its own): every value must come back where it was.
    from zendar_dataset.release.records import lidar_sweep

    rng = np.random.default_rng(3)
    n = 500
    t = 1.26e9 + rng.uniform(0, 0.1, n)
    g = np.asarray(POS) + rng.normal(size=(n, 3))
    local = rng.normal(size=(n, 3))
    intensity = rng.integers(0, 300, n)
    points = [enc.lidar_point(t[k], g[k], local[k], int(intensity[k])) for k in range(n)]
    points[300] = enc.f64(1, t[300]) + enc.ld(2, enc.vec3(*g[300])) + enc.uvar(4, int(intensity[300]))  # no position_local (past the points sniffing samples)
    path = enc.write_stream(tmp_path / "lidar.pbs", [enc.lidar_frame(1.26e9, points)])
    with ReleaseStream(path, kind="LidarPointsFrame") as stream:
        (_, buf, start, end), = list(stream.records())
        with pytest.raises(WireError, match="missing required field position_local"):
            lidar_sweep(stream.kind, buf, start, end)  # the final layout requires it
    points[300] = enc.lidar_point(t[300], g[300], local[300], 127)
    intensity[300] = 127
    path = enc.write_stream(tmp_path / "lidar.pbs", [enc.lidar_frame(1.26e9, points)])
    with ReleaseStream(path) as stream:
        (_, buf, start, end), = list(stream.records())
        sweep = lidar_sweep(stream.kind, buf, start, end)
    np.testing.assert_array_equal(sweep.position_ecef, g)
    np.testing.assert_array_equal(sweep.position_local, local)
    np.testing.assert_array_equal(sweep.intensity, intensity)


def test_lidar_columns_of_evenly_spaced_points_ending_the_file(tmp_path):
    # One layout for every point, the last one ending at the end of the file (the strided view's edge).
    from zendar_dataset.release.records import lidar_sweep

    rng = np.random.default_rng(4)
    g, local = np.asarray(POS) + rng.normal(size=(64, 3)), rng.normal(size=(64, 3))
    points = [enc.lidar_point(1.26e9, g[k], local[k], 5) for k in range(64)]
    path = enc.write_stream(tmp_path / "lidar.pbs", [enc.lidar_frame(1.26e9, points)], header=False)
    with ReleaseStream(path) as stream:
        (_, buf, start, end), = list(stream.records())
        assert end == len(buf)
        sweep = lidar_sweep(stream.kind, buf, start, end)
    np.testing.assert_array_equal(sweep.position_ecef, g)
    np.testing.assert_array_equal(sweep.position_local, local)
    assert np.all(sweep.intensity == 5)


def test_a_record_that_does_not_decode_is_reported_at_its_offset_or_skipped(tmp_path):
    records = [_image_2020(k) for k in range(4)]
    records[2] = b"\x0f" + records[2][1:]  # the first tag now says wire type 7
    path = enc.write_stream(tmp_path / "x_images.pbs", records)
    third = 8 + 2 * (4 + len(records[0]))
    with ReleaseStream(path) as stream, pytest.raises(ZendarFormatError, match=f"byte offset {third}.*does not decode"):
        list(stream)
    with ReleaseStream(path, skip_corrupt=True) as stream:
        assert [r["frame_id"] for r in stream] == [0, 1, 3]
        assert [(loss.offset, loss.size_bytes) for loss in stream.losses] == [(third, 4 + len(records[2]))]


def test_unknown_kind_name_is_a_user_error(tmp_path):
    from zendar_dataset.errors import ZendarError

    path = enc.write_stream(tmp_path / "vn200.pbs", [enc.position_record(1.26e9, ATT, POS, 1)])
    with pytest.raises(ZendarError, match="kind: expected one of .*'Position'.*, found 'Pose'"):
        ReleaseStream(path, kind="Pose")


@pytest.mark.parametrize("header", [True, False])
def test_sound_framing_with_unknown_content_is_unknown_not_truncated(tmp_path, header):
    # Framing is decided by the length prefixes alone: an index file tiles the file, so it is an
    # unknown message with the first mismatch, never "truncated or corrupt at byte offset 8".
    from zendar_dataset.release.stream import UnknownMessageError

    path = enc.write_stream(tmp_path / "index.pbs", [enc.time_index(1.26e9 + k, 1000 * k) for k in range(5)], header=header)
    for skip_corrupt in (False, True):
        with pytest.raises(UnknownMessageError, match="found none decodes") as info:
            ReleaseStream(path, skip_corrupt=skip_corrupt)
        assert "truncated" not in str(info.value)


def test_truncated_stream_of_unknown_content_is_still_truncated(tmp_path):
    data = enc.stream_bytes([enc.time_index(1.26e9 + k, k) for k in range(5)], header=False)
    path = tmp_path / "index.pbs"
    path.write_bytes(data[:-3])
    last = 4 * (4 + len(enc.time_index(1.26e9, 0)))
    with pytest.raises(ZendarFormatError, match=f"byte offset {last}.*only"):
        ReleaseStream(path)
