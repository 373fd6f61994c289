"""A small protobuf (proto2) wire decoder driven by message definitions held as data.

Why hand-written instead of the ``protobuf`` runtime: the release needs
schemas that no installable package carries (range-Doppler and camera exist
only in the 2020 repository file), two generations that parse *silently* into
each other under the runtime, and trial parses for sniffing that must reject a
record at the first wire-type mismatch or unknown field (the runtime accepts
both into unknown fields).  The bulk of the input bytes are ``bytes`` fields
(SAR images, range-Doppler cubes) that this decoder returns as zero-copy
``memoryview`` slices, so decoding costs little more than walking the tags.
Repeated sub-messages with many elements (detections, lidar points) go
through :func:`decode_repeated_columns`, which decodes every element with one
fixed layout as a strided numpy view and falls back to the generic decoder
only for elements laid out otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np

VARINT, FIXED64, LENGTH, FIXED32 = 0, 1, 2, 5

# Scalar field types: name -> (wire type, how to read it).
DOUBLE, FLOAT, UINT, INT32, BYTES, STRING = "double", "float", "uint", "int32", "bytes", "string"
_SCALAR_WIRE = {DOUBLE: FIXED64, FLOAT: FIXED32, UINT: VARINT, INT32: VARINT, BYTES: LENGTH, STRING: LENGTH}
_PACKABLE = {DOUBLE: "<f8", FLOAT: "<f4"}


class WireError(ValueError):
    """A buffer is not a valid encoding of the message it was decoded as.

    ``offset`` is the byte offset of the problem inside the decoded buffer.
    """

    def __init__(self, message: str, offset: int) -> None:
        super().__init__(message)
        self.offset = offset


@dataclass(frozen=True)
class Field:
    """One field of a message definition: its name, type (a scalar name or a :class:`Message`) and label."""

    name: str
    type: Any
    repeated: bool = False


@dataclass(frozen=True)
class Message:
    """A message definition: field number -> :class:`Field`, plus the fields a record must carry."""

    name: str
    fields: dict[int, Field]
    required: frozenset[int] = field(default_factory=frozenset)

    def wire_type(self, number: int) -> int:
        kind = self.fields[number].type
        return LENGTH if isinstance(kind, Message) else _SCALAR_WIRE[kind]


def read_varint(buf: memoryview, pos: int, end: int) -> tuple[int, int]:
    """Decode the varint at ``buf[pos]``; returns (value, position after it)."""
    result = 0
    shift = 0
    while pos < end:
        byte = buf[pos]
        pos += 1
        result |= (byte & 0x7F) << shift
        if byte < 0x80:
            return result, pos
        shift += 7
        if shift > 63:
            raise WireError("varint longer than 10 bytes", pos)
    raise WireError("varint runs past the end of the message", pos)


def iter_fields(buf: memoryview, start: int, end: int):
    """Yield ``(field number, wire type, value)`` for each field in ``buf[start:end]``.

    ``value`` is an int for varints, ``(offset, length)`` for length-delimited and
    fixed-width fields (so large payloads are never copied).
    """
    pos = start
    while pos < end:
        tag_at = pos
        tag, pos = read_varint(buf, pos, end)
        number, wire = tag >> 3, tag & 7
        if number == 0:
            raise WireError(f"field number 0 (tag byte 0x{tag:02x})", tag_at)
        if wire == VARINT:
            value, pos = read_varint(buf, pos, end)
            yield number, wire, value
        elif wire == FIXED64 or wire == FIXED32:
            size = 8 if wire == FIXED64 else 4
            if pos + size > end:
                raise WireError(f"field {number}: {size}-byte value runs past the end of the message", tag_at)
            yield number, wire, (pos, size)
            pos += size
        elif wire == LENGTH:
            length, pos = read_varint(buf, pos, end)
            if pos + length > end:
                raise WireError(
                    f"field {number}: declares {length} bytes, only {end - pos} left in the message", tag_at
                )
            yield number, wire, (pos, length)
            pos += length
        else:
            raise WireError(f"field {number}: unsupported wire type {wire}", tag_at)


def _scalar(kind: str, buf: memoryview, value: Any) -> Any:
    if kind == DOUBLE:
        return float(np.frombuffer(buf, "<f8", 1, value[0])[0])
    if kind == FLOAT:
        return float(np.frombuffer(buf, "<f4", 1, value[0])[0])
    if kind == UINT:
        return value
    if kind == INT32:
        value &= 0xFFFFFFFF  # negative int32 arrive as 10-byte varints
        return value - (1 << 32) if value >= 1 << 31 else value
    start, length = value
    if kind == BYTES:
        return buf[start : start + length]
    return bytes(buf[start : start + length]).decode("utf-8", errors="replace")


def decode(
    message: Message, buf: memoryview, start: int = 0, end: int | None = None, unknown: dict[str, int] | None = None
) -> dict[str, Any]:
    """Decode ``buf[start:end]`` as ``message``, strictly.

    Strict means: an unknown field number, a wire type that differs from the
    definition or a missing required field raises :class:`WireError`.  This is
    what tells the schema generations apart, which parse into each other
    silently under a lenient decoder.  Repeated scalars are accepted packed or not.

    Parameters
    ----------
    unknown
        None: an unknown field number raises.  A dict (once the message kind is decided):
        unknown fields are skipped and counted in it, keyed ``"<Message>.<number>"``.

    Returns
    -------
    dict
        Field name -> value (float, int, str, ``memoryview`` for bytes, dict for
        sub-messages, list for repeated fields); absent fields are missing.
    """
    end = len(buf) if end is None else end
    out: dict[str, Any] = {}
    seen = set()
    for number, wire, value in iter_fields(buf, start, end):
        spec = message.fields.get(number)
        if spec is None:
            if unknown is None:
                raise WireError(f"{message.name}: unknown field {number} (wire type {wire})", start)
            count_unknown(unknown, message, number)
            continue
        expected = message.wire_type(number)
        kind = spec.type
        if wire != expected:
            if spec.repeated and wire == LENGTH and isinstance(kind, str) and kind in _PACKABLE:
                offset, length = value
                dtype = np.dtype(_PACKABLE[kind])
                out.setdefault(spec.name, []).extend(np.frombuffer(buf, dtype, length // dtype.itemsize, offset).tolist())
                seen.add(number)
                continue
            raise WireError(
                f"{message.name}.{spec.name} (field {number}): expected wire type {expected}, found {wire}", start
            )
        if isinstance(kind, Message):
            offset, length = value
            item: Any = decode(kind, buf, offset, offset + length, unknown)
        else:
            item = _scalar(kind, buf, value)
        if spec.repeated:
            out.setdefault(spec.name, []).append(item)
        elif spec.name in out:
            # Writers never repeat a singular field; a repeat means the bytes are another message.
            raise WireError(f"{message.name}.{spec.name} (field {number}): appears twice", start)
        else:
            out[spec.name] = item
        seen.add(number)
    missing = message.required - seen
    if missing:
        names = ", ".join(f"{message.fields[n].name} ({n})" for n in sorted(missing))
        raise WireError(f"{message.name}: missing required field {names}", start)
    return out


def count_unknown(unknown: dict[str, int], message: Message, number: int) -> None:
    """Count one occurrence of field ``number``, which ``message`` does not define."""
    key = f"{message.name}.{number}"
    unknown[key] = unknown.get(key, 0) + 1


@numba.njit(cache=True, nogil=True, inline="always")
def _varint_compiled(data: np.ndarray, pos: int, end: int):  # pragma: no cover - compiled
    """:func:`read_varint` for the compiled scan: ``(value, next position, complete)``."""
    value = 0
    shift = 0
    while True:
        if pos >= end or shift > 63:
            return value, pos, False
        byte = data[pos]
        pos += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if byte < 0x80:
            return value, pos, True


@numba.njit(cache=True, nogil=True)
def _scan(data: np.ndarray, start: int, end: int):  # pragma: no cover - compiled
    """Top-level fields of ``data[start:end]``: number, wire type, value or payload offset, payload length.

    Compiled because repeated sub-messages (lidar points, detections) run to
    tens of thousands per record, and walking their tags is inherently
    sequential.  Returns ``error_at >= 0`` where the encoding breaks.
    """
    capacity = max(16, (end - start) // 2)
    numbers = np.empty(capacity, np.int64)
    wires = np.empty(capacity, np.int64)
    values = np.empty(capacity, np.int64)
    lengths = np.empty(capacity, np.int64)
    n = 0
    pos = start
    while pos < end:
        tag_at = pos
        tag, pos, ok = _varint_compiled(data, pos, end)
        if not ok:
            return numbers[:n], wires[:n], values[:n], lengths[:n], tag_at
        number = tag >> 3
        wire = tag & 7
        value = 0
        length = 0
        if number == 0:
            return numbers[:n], wires[:n], values[:n], lengths[:n], tag_at
        if wire == 0 or wire == 2:
            value, pos, ok = _varint_compiled(data, pos, end)
            if not ok:
                return numbers[:n], wires[:n], values[:n], lengths[:n], tag_at
            if wire == 2:
                length = value
                value = pos
                if length > end - pos:
                    return numbers[:n], wires[:n], values[:n], lengths[:n], tag_at
                pos += length
        elif wire == 1 or wire == 5:
            length = 8 if wire == 1 else 4
            value = pos
            if pos + length > end:
                return numbers[:n], wires[:n], values[:n], lengths[:n], tag_at
            pos += length
        else:
            return numbers[:n], wires[:n], values[:n], lengths[:n], tag_at
        numbers[n] = number
        wires[n] = wire
        values[n] = value
        lengths[n] = length
        n += 1
    return numbers[:n], wires[:n], values[:n], lengths[:n], -1


def check(message: Message, buf: memoryview, start: int = 0, end: int | None = None, sample: int = 8) -> frozenset[int]:
    """Raise :class:`WireError` unless ``buf[start:end]`` is a strict encoding of ``message``.

    The same rules as :func:`decode` (no unknown field, matching wire types, singular fields
    once, required fields present), checked on every top-level field but only on the first
    ``sample`` elements of each repeated sub-message, so sniffing a 30 000-point lidar sweep
    costs microseconds rather than a full decode.  Returns the top-level field numbers present.
    """
    end = len(buf) if end is None else end
    numbers, wires, values, lengths, error_at = _scan(np.frombuffer(buf, np.uint8), start, end)
    if error_at >= 0:
        list(iter_fields(buf, error_at, end))  # raises WireError with the reason
        raise WireError(f"{message.name}: malformed field", error_at)
    present, counts = np.unique(numbers, return_counts=True)
    for number, count in zip(present.tolist(), counts.tolist()):
        spec = message.fields.get(number)
        where = np.flatnonzero(numbers == number)
        if spec is None:
            raise WireError(f"{message.name}: unknown field {number} (wire type {int(wires[where[0]])})", start)
        expected = message.wire_type(number)
        wrong = wires[where] != expected
        if spec.repeated and isinstance(spec.type, str) and spec.type in _PACKABLE:
            wrong &= wires[where] != LENGTH  # packed
        if np.any(wrong):
            found = int(wires[where[np.argmax(wrong)]])
            raise WireError(f"{message.name}.{spec.name} (field {number}): expected wire type {expected}, found {found}", start)
        if not spec.repeated and count > 1:
            raise WireError(f"{message.name}.{spec.name} (field {number}): appears twice", start)
        if isinstance(spec.type, Message):
            for k in where[:sample].tolist():
                check(spec.type, buf, int(values[k]), int(values[k] + lengths[k]), sample)
    missing = message.required - set(present.tolist())
    if missing:
        names = ", ".join(f"{message.fields[n].name} ({n})" for n in sorted(missing))
        raise WireError(f"{message.name}: missing required field {names}", start)
    return frozenset(present.tolist())


def repeated_spans(buf: memoryview, start: int, end: int, number: int) -> tuple[np.ndarray, np.ndarray, dict[int, list]]:
    """Offsets and lengths of every occurrence of length-delimited field ``number``, and the other fields.

    Returns
    -------
    offsets, lengths : np.ndarray, int64, [n]
        Payload position and size of each occurrence, in buffer order.
    others : dict
        Field number -> list of ``(wire type, value)`` for every other field.
    """
    numbers, wires, values, lengths, error_at = _scan(np.frombuffer(buf, np.uint8), start, end)
    if error_at >= 0:
        list(iter_fields(buf, error_at, end))  # raises WireError with the reason
    bulk = (numbers == number) & (wires == LENGTH)
    others: dict[int, list] = {}
    for i in np.flatnonzero(~bulk):
        wire = int(wires[i])
        value = int(values[i]) if wire == VARINT else (int(values[i]), int(lengths[i]))
        others.setdefault(int(numbers[i]), []).append((wire, value))
    return values[bulk], lengths[bulk], others


@dataclass(frozen=True)
class Column:
    """Where a numeric value sits inside a fixed-layout element: byte offset in the payload and dtype."""

    name: str
    offset: int
    dtype: str
    signed32: bool = False  # an int32 varint: the low 32 bits, two's complement


def _layout(message: Message, buf: memoryview, start: int, end: int) -> tuple[bytes, list[Column]] | None:
    """The tag bytes and value positions of one element, when every value has a fixed width.

    Returns None when the element holds a varint or a nested field of variable size (those
    elements take the generic path).
    """
    columns: list[Column] = []
    for number, wire, value, position, after in _fields_with_positions(buf, start, end):
        spec = message.fields.get(number)
        if spec is None or spec.repeated:
            return None
        kind = spec.type
        if isinstance(kind, Message):
            offset, length = value
            inner = _layout(kind, buf, offset, offset + length)
            if inner is None:
                return None
            columns.extend(Column(f"{spec.name}.{c.name}", c.offset + offset - start, c.dtype) for c in inner[1])
        elif kind in (DOUBLE, FLOAT) and wire == message.wire_type(number):
            columns.append(Column(spec.name, value[0] - start, "<f8" if kind == DOUBLE else "<f4"))
        elif kind in (UINT, INT32) and wire == VARINT:
            columns.append(Column(spec.name, position - start, f"varint{after - position}", kind == INT32))
        else:
            return None
    # The tag skeleton: every byte that is not a value. Elements with the same skeleton share the layout.
    mask = _skeleton_mask(end - start, columns)
    tags = bytes(np.frombuffer(buf, np.uint8, end - start, start)[mask])
    return tags, columns


def _width(column: Column) -> int:
    return int(column.dtype[6:]) if column.dtype.startswith("varint") else np.dtype(column.dtype).itemsize


def _skeleton_mask(size: int, columns: list[Column]) -> np.ndarray:
    mask = np.ones(size, bool)
    for column in columns:
        mask[column.offset : column.offset + _width(column)] = False
    return mask


def _fields_with_positions(buf: memoryview, start: int, end: int):
    """:func:`iter_fields` plus where each varint value starts and ends."""
    pos = start
    for number, wire, value in iter_fields(buf, start, end):
        _, value_at = read_varint(buf, pos, end)  # skip the tag
        if wire == VARINT:
            _, after = read_varint(buf, value_at, end)
        elif wire == LENGTH:
            after = value[0] + value[1]
        else:
            after = value[0] + value[1]
        yield number, wire, value, value_at, after
        pos = after


def _record_dtype(size: int, columns: list[Column], tags: bytes) -> tuple[np.dtype, list[tuple[str, bytes]]]:
    """A structured dtype over one element: a field per value (per byte for varints) and per run of tag bytes."""
    names, formats, offsets = [], [], []
    for column in columns:
        if column.dtype.startswith("varint"):
            for k in range(_width(column)):
                names.append(f"{column.name}#{k}")
                formats.append("u1")
                offsets.append(column.offset + k)
        else:
            names.append(column.name)
            formats.append(column.dtype)
            offsets.append(column.offset)
    mask = _skeleton_mask(size, columns)
    runs: list[tuple[str, bytes]] = []
    position = 0
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.view(np.int8), [0]])))
    for run, (begin, stop) in enumerate(zip(edges[::2], edges[1::2])):
        name = f"#tags{run}"
        names.append(name)
        formats.append(f"V{stop - begin}")
        offsets.append(int(begin))
        runs.append((name, tags[position : position + stop - begin]))
        position += stop - begin
    return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": size}), runs


def _records(data: np.ndarray, offsets: np.ndarray, size: int, columns: list[Column], tags: bytes):
    """The elements at ``offsets`` as a structured array: a strided view when evenly spaced, else a gathered copy."""
    steps = np.diff(offsets)
    dtype, runs = _record_dtype(size, columns, tags)
    if offsets.size == 1 or (np.all(steps == steps[0]) and steps[0] >= size):
        step = int(steps[0]) if offsets.size > 1 else size
        return np.ndarray((offsets.size,), dtype, buffer=data, offset=int(offsets[0]), strides=(step,)), runs
    # Every byte position as the start of an opaque V<size> element (a view, nothing copied): indexing
    # it copies each chosen element whole (a structured dtype would be copied field by field, and a
    # byte-wise gather needs an index per byte).
    starts = np.ndarray((data.size - size + 1,), f"V{size}", buffer=data, offset=0, strides=(1,))
    return starts[offsets].view(dtype), runs


def _record_values(records: np.ndarray, column: Column) -> tuple[np.ndarray, np.ndarray]:
    """One column as float64 and which elements encode it as laid out (varint continuation bits)."""
    if not column.dtype.startswith("varint"):
        return records[column.name].astype(np.float64), np.ones(records.shape[0], bool)
    width = _width(column)
    parts = [records[f"{column.name}#{k}"] for k in range(width)]
    ok = np.ones(records.shape[0], bool)
    value = np.zeros(records.shape[0], np.uint64)
    for k, part in enumerate(parts):
        ok &= (part >= 0x80) if k < width - 1 else (part < 0x80)
        value |= (part.astype(np.uint64) & np.uint64(0x7F)) << np.uint64(7 * k)
    if column.signed32:
        return (value & np.uint64(0xFFFFFFFF)).astype(np.uint32).view(np.int32).astype(np.float64), ok
    return value.astype(np.float64), ok


def decode_repeated_columns(
    element: Message, buf: memoryview, offsets: np.ndarray, lengths: np.ndarray, unknown: dict[str, int] | None = None
) -> tuple[dict[str, np.ndarray], list[int]]:
    """Decode many encodings of one message column-wise into numpy arrays.

    The elements are the payloads at ``offsets`` (``lengths`` bytes each): the occurrences of a
    repeated sub-message, or the records of a stream.

    Elements whose encoding has the same length and tag skeleton as the first
    all-fixed-width element are read as strided views (no per-element Python
    work); the rest are returned by index for the generic decoder.

    ``unknown`` is :func:`decode`'s (elements with unknown fields take the generic path).

    Returns
    -------
    columns : dict
        Dotted field name (``"position.x"``) -> ``[n]`` array, NaN where the fast path did not apply.
    slow : list of int
        Indices of the elements the caller must decode with :func:`decode`.
    """
    n = offsets.shape[0]
    data = np.frombuffer(buf, np.uint8)
    slow: list[int] = []
    columns: dict[str, np.ndarray] = {}
    if n == 0:
        return columns, slow
    done = np.zeros(n, bool)
    remaining = np.arange(n)
    for _ in range(8):  # a few distinct layouts (e.g. one-byte vs two-byte lengths) cover real streams
        if remaining.size == 0:
            break
        first = int(remaining[0])
        layout = _layout(element, buf, int(offsets[first]), int(offsets[first] + lengths[first]))
        if layout is None:
            break
        decode(element, buf, int(offsets[first]), int(offsets[first] + lengths[first]), unknown)  # strict check once
        tags, cols = layout
        size = int(lengths[first])
        same_length = remaining[lengths[remaining] == size]
        records, runs = _records(data, offsets[same_length], size, cols, tags)
        match = np.ones(same_length.size, bool)
        for name, expected in runs:
            match &= records[name] == np.array(expected, dtype=records.dtype[name])
        values = {}
        for column in cols:
            values[column.name], ok = _record_values(records, column)
            match &= ok
        chosen = same_length[match]
        for name, column_values in values.items():
            columns.setdefault(name, np.full(n, np.nan))[chosen] = column_values[match]
        done[chosen] = True
        remaining = np.flatnonzero(~done)
    slow.extend(int(i) for i in np.flatnonzero(~done))
    return columns, slow
