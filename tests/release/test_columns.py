"""The column decoder against the plain per-message decoder: the same values, unknown-field counts and errors.

``records._columns`` (the compiled loop, with the generic decoder for the elements it hands back) and
``columns.decode_repeated_field`` (a record's repeated field, decoded as the top level is walked) must give
exactly what decoding every element with ``wire.decode`` gives: bit-identical values, NaN where a field is
absent, the same counts of unknown fields, and for malformed input the same ``WireError`` (message and
offset) for the first element that does not decode.
"""

from __future__ import annotations

import struct

import numpy as np
import pytest

from tests.release import encoder as enc
from zendar_dataset.release import messages as m
from zendar_dataset.release import records as rec
from zendar_dataset.release import columns, wire
from zendar_dataset.release.columns import column_table, decode_repeated_field
from zendar_dataset.release.wire import WireError, check, decode

POS = (-2_706_000.25, -4_261_000.5, 3_885_000.75)


def _elements(payloads: list[bytes]) -> tuple[memoryview, np.ndarray, np.ndarray]:
    """The payloads back to back after a few bytes of padding (so no element starts at offset 0)."""
    buf = b"\xff" * 3 + b"".join(payloads)
    lengths = np.array([len(p) for p in payloads], np.int64)
    offsets = 3 + np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64)
    return memoryview(buf), offsets, lengths


def _plain(element, buf, offsets, lengths, unknown):
    """Every element through ``wire.decode``, one at a time, into the column decoder's table layout."""
    names = column_table(element).names
    values = np.full((offsets.shape[0], len(names)), np.nan)
    for k, (offset, length) in enumerate(zip(offsets.tolist(), lengths.tolist())):
        for name, value in rec._flatten(decode(element, buf, offset, offset + length, unknown)):
            values[k, names.index(name)] = value
    return values


def _outcome(function):
    """What ``function`` returns, or the WireError it raises as (message, offset)."""
    try:
        return "values", function()
    except WireError as exc:
        return "error", (str(exc), exc.offset)


def _assert_same(element, payloads: list[bytes], counting: bool) -> None:
    buf, offsets, lengths = _elements(payloads)
    plain_unknown = {} if counting else None
    fast_unknown = {} if counting else None
    expected = _outcome(lambda: _plain(element, buf, offsets, lengths, plain_unknown))
    actual = _outcome(lambda: rec._columns(element, buf, offsets, lengths, fast_unknown).values)
    assert actual[0] == expected[0], (actual, expected)
    if expected[0] == "error":
        assert actual[1] == expected[1]
        return
    # Bit for bit: NaN payloads, -0.0 and infinities included.
    np.testing.assert_array_equal(actual[1].view(np.uint64), expected[1].view(np.uint64))
    assert fast_unknown == plain_unknown


def _point(rng: np.random.Generator) -> bytes:
    """A ``Point`` with its required fields and a random subset of the optional ones, in random order."""
    fields = [enc.ld(1, enc.time_record(1.26e9 + rng.uniform(), sensor=float(rng.uniform()))), enc.ld(2, enc.vec3(*(np.asarray(POS) + rng.normal(size=3))))]
    special = [float("nan"), float("inf"), -float("inf"), -0.0, 3.4e38, 1e-45]
    for number in range(3, 12):
        if rng.uniform() < 0.7:
            value = special[rng.integers(len(special))] if rng.uniform() < 0.1 else float(rng.normal())
            fields.append(enc.f32(number, value))
    return b"".join(fields[k] for k in rng.permutation(len(fields)))


def _position(rng: np.random.Generator) -> bytes:
    quality = enc.uvar(1, int(rng.integers(-3, 20))) + enc.uvar(2, int(rng.integers(0, 1 << 40))) + enc.uvar(3, 2)
    fields = [
        enc.f64(1, 1.26e9 + rng.uniform()),
        enc.ld(2, enc.quaternion(rng.normal(size=4))),
        enc.ld(3, enc.vec3(*POS)),
        enc.uvar(4, int(rng.integers(0, 1 << 63))),
    ]
    if rng.uniform() < 0.5:
        fields.append(enc.ld(5, quality))
    return b"".join(fields[k] for k in rng.permutation(len(fields)))


def _lidar_point(rng: np.random.Generator) -> bytes:
    intensity = int(rng.choice([rng.integers(0, 128), rng.integers(128, 1 << 14), rng.integers(0, 1 << 63)]))
    return enc.lidar_point(1.26e9 + rng.uniform(), np.asarray(POS) + rng.normal(size=3), rng.normal(size=3), intensity)


MAKERS = {"Point": (m.POINT_2021, _point), "Position": (m.POSITION, _position), "LidarPoint": (m.LIDAR_POINT, _lidar_point)}


@pytest.mark.parametrize("name", sorted(MAKERS))
def test_valid_elements_in_any_field_order_decode_as_the_plain_decoder_does(name):
    element, make = MAKERS[name]
    rng = np.random.default_rng(7)
    _assert_same(element, [make(rng) for _ in range(400)], counting=False)


@pytest.mark.parametrize("name", sorted(MAKERS))
def test_on_a_big_endian_host_floats_go_to_the_plain_decoder(name, monkeypatch):
    # The compiled loop loads floats as they lie in memory: right on little-endian hosts only.
    monkeypatch.setattr(columns, "_NATIVE_FLOATS", False)
    monkeypatch.setattr(columns, "_TABLES", {})
    element, make = MAKERS[name]
    rng = np.random.default_rng(8)
    payloads = [make(rng) for _ in range(50)]
    buf, offsets, lengths = _elements(payloads)
    _, slow = columns.decode_repeated_columns(element, buf, offsets, lengths)
    assert slow == list(range(len(payloads)))  # every element has a float or double
    _assert_same(element, payloads, counting=False)


# Elements the compiled loop must hand back to the generic decoder, which decodes (or rejects) them.
ODD_POINTS = {
    "unknown field": lambda p: p + enc.f32(12, 1.5),
    "unknown field, two-byte tag": lambda p: p + enc.f32(40, 1.5),
    "unknown field in a sub-message": lambda p: enc.ld(2, enc.vec3(*POS) + enc.f64(7, 1.0)) + enc.ld(1, enc.time_record(1.26e9)),
    "wrong wire type": lambda p: p + enc.uvar(6, 3),
    "sub-message as a double": lambda p: enc.f64(1, 1.26e9) + enc.ld(2, enc.vec3(*POS)),
    "singular field twice": lambda p: p + enc.f32(6, 1.0) + enc.f32(6, 2.0),
    "required field missing": lambda p: enc.ld(1, enc.time_record(1.26e9)) + enc.f32(6, 1.0),
    "required sub-field missing": lambda p: enc.ld(1, enc.f64(2, 1.0)) + enc.ld(2, enc.vec3(*POS)),
    "empty element": lambda p: b"",
    "float cut short": lambda p: p + enc.key(6, 5) + b"\x00\x00",
    "sub-message longer than the element": lambda p: p + enc.key(2, 2) + enc.varint(200) + enc.vec3(*POS),
    "field number 0": lambda p: p + b"\x05" + struct.pack("<f", 1.0),
    "wire type 7": lambda p: p + b"\x37",
    "tag varint cut short": lambda p: p + b"\x85",
    "non-minimal tag": lambda p: b"\xb5\x00" + struct.pack("<f", 2.5) + enc.ld(1, enc.time_record(1.26e9)) + enc.ld(2, enc.vec3(*POS)),
}

ODD_POSITIONS = {
    "uint past 64 bits": lambda p: enc.f64(1, 1.26e9) + enc.ld(2, enc.quaternion((1, 0, 0, 0))) + enc.ld(3, enc.vec3(*POS))
    + enc.key(4, 0) + b"\xff" * 9 + b"\x03",
    "eleven-byte varint": lambda p: p + enc.key(4, 0) + b"\xff" * 10 + b"\x01",
    "negative int32 in a sub-message": lambda p: enc.f64(1, 1.26e9) + enc.ld(2, enc.quaternion((1, 0, 0, 0))) + enc.ld(3, enc.vec3(*POS))
    + enc.ld(5, enc.uvar(1, -7)),
}


@pytest.mark.parametrize("counting", [False, True], ids=["unknown raises", "unknown counted"])
@pytest.mark.parametrize("case", sorted(ODD_POINTS))
def test_odd_and_malformed_points_give_the_plain_decoders_values_counts_and_errors(case, counting):
    rng = np.random.default_rng(11)
    payloads = [_point(rng) for _ in range(300)]
    for k in (5, 170):  # two of them: the first decides the error
        payloads[k] = ODD_POINTS[case](payloads[k])
    _assert_same(m.POINT_2021, payloads, counting)


@pytest.mark.parametrize("case", sorted(ODD_POSITIONS))
def test_odd_and_malformed_positions_give_the_plain_decoders_values_and_errors(case):
    rng = np.random.default_rng(12)
    payloads = [_position(rng) for _ in range(100)]
    payloads[40] = ODD_POSITIONS[case](payloads[40])
    _assert_same(m.POSITION, payloads, counting=False)


def _detections_plain(kind, buf, start, end, unknown):
    """Per-detection columns from the record's points decoded one at a time with ``wire.decode``."""
    element = kind.message.fields[2].type
    spans = [(value[0], value[1]) for number, wire_type, value in wire.iter_fields(buf, start, end) if number == 2]
    offsets, lengths = np.array([s[0] for s in spans], np.int64), np.array([s[1] for s in spans], np.int64)
    return _plain(element, buf, offsets, lengths, unknown)


@pytest.mark.parametrize("case", ["valid", "unknown field", "float cut short", "required field missing"])
def test_a_tracker_state_decodes_as_its_points_one_by_one(case):
    rng = np.random.default_rng(13)
    points = [_point(rng) for _ in range(250)]
    if case != "valid":
        points[90] = ODD_POINTS[case](points[90])
    record = enc.ld(1, enc.metadata(1.26e9, frame_id=3)) + b"".join(enc.ld(2, p) for p in points)
    buf = memoryview(b"\x00" * 5 + record)
    kind = next(k for k in m.KINDS if k.label == "TrackerState (2021)")
    plain_unknown, fast_unknown = {}, {}
    expected = _outcome(lambda: _detections_plain(kind, buf, 5, len(buf), plain_unknown))
    actual = _outcome(lambda: rec.detections(kind, buf, 5, len(buf), fast_unknown))
    assert actual[0] == expected[0]
    if expected[0] == "error":
        assert actual[1] == expected[1]
        return
    names = column_table(kind.message.fields[2].type).names
    for ours, theirs in {"range_m": "range", "magnitude": "magnitude", "snr": "doa_snr"}.items():
        np.testing.assert_array_equal(actual[1].columns[ours].view(np.uint64), expected[1][:, names.index(theirs)].view(np.uint64))
    xyz = [names.index(f"position.{axis}") for axis in "xyz"]
    np.testing.assert_array_equal(actual[1].columns["position_ecef"], expected[1][:, xyz])
    assert fast_unknown == plain_unknown


@pytest.mark.parametrize("cut", [1, 2, 5, 40])
def test_a_record_cut_short_raises_the_plain_decoders_error(cut):
    rng = np.random.default_rng(14)
    record = enc.lidar_frame(1.26e9, [_lidar_point(rng) for _ in range(30)])
    buf = memoryview(record[:-cut])
    with pytest.raises(WireError) as plain:
        list(wire.iter_fields(buf, 0, len(buf)))
    with pytest.raises(WireError) as fast:
        decode_repeated_field(m.LIDAR_POINT, 2, buf, 0, len(buf))
    assert (str(fast.value), fast.value.offset) == (str(plain.value), plain.value.offset)


def test_a_length_past_63_bits_is_reported_where_it_is():
    # A ten-byte length prefix reads as a negative int64 in compiled code: it must not step backwards.
    record = enc.f64(1, 1.26e9) + enc.key(2, 2) + b"\xff" * 9 + b"\x01" + bytes(20)
    buf = memoryview(record)
    with pytest.raises(WireError) as plain:
        decode(m.LIDAR_FRAME, buf)
    for fast in (lambda: check(m.LIDAR_FRAME, buf), lambda: decode_repeated_field(m.LIDAR_POINT, 2, buf, 0, len(buf))):
        with pytest.raises(WireError) as caught:
            fast()
        assert (str(caught.value), caught.value.offset) == (str(plain.value), plain.value.offset)


@pytest.mark.parametrize("case", ["valid", "wrong wire type", "unknown field", "singular field twice", "required field missing"])
def test_sniffing_checks_give_one_verdict_whichever_way_fields_are_grouped(case, monkeypatch):
    # Few fields are grouped in Python, many with numpy: the same message either way.
    rng = np.random.default_rng(15)
    points = b"".join(enc.ld(2, _point(rng)) for _ in range(3))
    record = {
        "valid": enc.ld(1, enc.metadata(1.26e9)) + points,
        "wrong wire type": enc.ld(1, enc.metadata(1.26e9)) + points + enc.f64(1, 1.0),
        "unknown field": enc.ld(1, enc.metadata(1.26e9)) + points + enc.f32(9, 1.0),
        "singular field twice": enc.ld(1, enc.metadata(1.26e9)) + points + enc.ld(1, enc.metadata(1.27e9)),
        "required field missing": points + enc.uvar(3, 7),  # the 2020 form requires its timestamp
    }[case]
    message = m.TRACKER_STATE_2020 if case == "required field missing" else m.TRACKER_STATE_2021
    outcomes = []
    for few in (0, 1000):
        monkeypatch.setattr(wire, "_FEW_FIELDS", few)
        outcomes.append(_outcome(lambda: check(message, memoryview(record))))
    assert outcomes[0] == outcomes[1]
    assert outcomes[0][0] == ("values" if case == "valid" else "error")
