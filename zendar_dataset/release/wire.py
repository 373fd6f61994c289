"""A small protobuf (proto2) wire decoder driven by message definitions held as data.

Why hand-written instead of the ``protobuf`` runtime: the release needs
schemas that no installable package carries (range-Doppler and camera exist
only in the 2020 repository file), two generations that parse *silently* into
each other under the runtime, and trial parses for sniffing that must reject a
record at the first wire-type mismatch or unknown field (the runtime accepts
both into unknown fields).  The bulk of the input bytes are ``bytes`` fields
(SAR images, range-Doppler cubes) that this decoder returns as zero-copy
``memoryview`` slices, so decoding costs little more than walking the tags.
Repeated sub-messages with many elements (detections, lidar points) are
decoded column-wise by ``release/columns.py``, which falls back to
:func:`decode` for any element it does not accept.
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
def read_varint_compiled(data: np.ndarray, pos: int, end: int):  # pragma: no cover - compiled
    """:func:`read_varint` for compiled walks: ``(value, next position, complete)``; a value past 63 bits
    comes out negative."""
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
        tag, pos, ok = read_varint_compiled(data, pos, end)
        if not ok:
            return numbers[:n], wires[:n], values[:n], lengths[:n], tag_at
        number = tag >> 3
        wire = tag & 7
        value = 0
        length = 0
        if number == 0:
            return numbers[:n], wires[:n], values[:n], lengths[:n], tag_at
        if wire == 0 or wire == 2:
            value, pos, ok = read_varint_compiled(data, pos, end)
            if not ok:
                return numbers[:n], wires[:n], values[:n], lengths[:n], tag_at
            if wire == 2:
                length = value
                value = pos
                if length < 0 or length > end - pos:  # negative: a varint past 63 bits
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


@dataclass
class Scanned:
    """The top-level fields of a message's bytes (:func:`scan`), for :func:`check` to test several messages
    against without walking or grouping them again.

    Attributes
    ----------
    numbers, wires, values, lengths : ndarray, [n], int64
        Field numbers, wire types, values (varints) or payload offsets, payload lengths.
    error_at : int
        Offset where the encoding breaks, -1 when it does not.
    """

    numbers: np.ndarray
    wires: np.ndarray
    values: np.ndarray
    lengths: np.ndarray
    error_at: int
    _groups: dict[int, list] = field(default_factory=dict, init=False, repr=False)  # per sample size

    def groups(self, sample: int) -> list[tuple[int, int, list[int], list[int]]]:
        """Per field number present, in increasing order: how often it occurs, its distinct wire types in order
        of first occurrence, and the indices of its first ``sample`` occurrences."""
        if sample not in self._groups:
            self._groups[sample] = _field_groups(self.numbers, self.wires, sample)
        return self._groups[sample]


def scan(buf: memoryview, start: int, end: int) -> Scanned:
    """The top-level fields of ``buf[start:end]``."""
    return Scanned(*_scan(np.frombuffer(buf, np.uint8), start, end))


def check(
    message: Message, buf: memoryview, start: int = 0, end: int | None = None, sample: int = 8, scanned: Scanned | None = None
) -> frozenset[int]:
    """Raise :class:`WireError` unless ``buf[start:end]`` is a strict encoding of ``message``.

    The same rules as :func:`decode` (no unknown field, matching wire types, singular fields
    once, required fields present), checked on every top-level field but only on the first
    ``sample`` elements of each repeated sub-message, so sniffing a 30 000-point lidar sweep
    costs microseconds rather than a full decode.  ``scanned``: :func:`scan` of the same bytes,
    when several messages are checked against one record (sniffing).  Returns the top-level
    field numbers present.
    """
    end = len(buf) if end is None else end
    scanned = scanned if scanned is not None else scan(buf, start, end)
    values, lengths, error_at = scanned.values, scanned.lengths, scanned.error_at
    if error_at >= 0:
        list(iter_fields(buf, error_at, end))  # raises WireError with the reason
        raise WireError(f"{message.name}: malformed field", error_at)
    present = []
    for number, count, distinct_wires, first in scanned.groups(sample):
        present.append(number)
        spec = message.fields.get(number)
        if spec is None:
            raise WireError(f"{message.name}: unknown field {number} (wire type {distinct_wires[0]})", start)
        expected = message.wire_type(number)
        packed = spec.repeated and isinstance(spec.type, str) and spec.type in _PACKABLE
        wrong = [wire for wire in distinct_wires if wire != expected and not (packed and wire == LENGTH)]
        if wrong:
            raise WireError(f"{message.name}.{spec.name} (field {number}): expected wire type {expected}, found {wrong[0]}", start)
        if not spec.repeated and count > 1:
            raise WireError(f"{message.name}.{spec.name} (field {number}): appears twice", start)
        if isinstance(spec.type, Message):
            for k in first:
                check(spec.type, buf, int(values[k]), int(values[k] + lengths[k]), sample)
    missing = message.required - set(present)
    if missing:
        names = ", ".join(f"{message.fields[n].name} ({n})" for n in sorted(missing))
        raise WireError(f"{message.name}: missing required field {names}", start)
    return frozenset(present)


_FEW_FIELDS = 64  # below this, grouping fields in Python beats a dozen numpy calls per message


def _field_groups(numbers: np.ndarray, wires: np.ndarray, sample: int) -> list[tuple[int, int, list[int], list[int]]]:
    """Per field number present, in increasing order: how often it occurs, its distinct wire types in order
    of first occurrence, and the indices of its first ``sample`` occurrences."""
    if numbers.shape[0] < _FEW_FIELDS:
        groups: dict[int, tuple[list[int], dict[int, None], list[int]]] = {}
        for k, (number, wire) in enumerate(zip(numbers.tolist(), wires.tolist())):
            count, distinct, first = groups.setdefault(number, ([0], {}, []))
            count[0] += 1
            distinct.setdefault(wire)
            if len(first) < sample:
                first.append(k)
        return [(number, count[0], list(distinct), first) for number, (count, distinct, first) in sorted(groups.items())]
    out = []
    present, counts = np.unique(numbers, return_counts=True)
    for number, count in zip(present.tolist(), counts.tolist()):
        where = np.flatnonzero(numbers == number)
        distinct, first_at = np.unique(wires[where], return_index=True)
        out.append((number, count, distinct[np.argsort(first_at)].tolist(), where[:sample].tolist()))
    return out
