"""Column-wise decoding of many encodings of one message: every numeric field into a ``[n]`` float64 column.

Repeated sub-messages with tens of thousands of elements (lidar points, detections) and streams of many
small records (the tracklog) would cost a few µs per field through the generic decoder
(:func:`zendar_dataset.release.wire.decode`).  Here the message definition is flattened once into a
small table (per nested message: tag -> what to do with the field) and one compiled loop walks every
element's tags and writes its values straight into a ``[n, columns]`` table: no per-element Python
object, whatever the mix of varint widths or field orders.  A record's repeated field is decoded while
the record's top level is walked, each element as the walk reaches it.

The compiled loop accepts only what the generic decoder accepts without help: known numeric fields
and singular sub-messages, each once, with the definition's wire type, required fields present.  Any
other element (an unknown field, a ``bytes`` field, a repeated field inside the element, a malformed
or truncated encoding, a varint past 64 bits) is handed back by index, for the generic decoder to
decode, count unknown fields in, or raise its :class:`~zendar_dataset.release.wire.WireError` for: the
values, counts and errors are the generic decoder's by construction.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from zendar_dataset.release.wire import (
    DOUBLE, FIXED32, FIXED64, FLOAT, INT32, LENGTH, UINT, VARINT, Message, WireError, iter_fields, read_varint_compiled,
)

# What the compiled loop does with a field (the table's actions).
_REJECT, _DOUBLE, _FLOAT, _UINT, _INT32, _MESSAGE = 0, 1, 2, 3, 4, 5
_CODES = {DOUBLE: _DOUBLE, FLOAT: _FLOAT, UINT: _UINT, INT32: _INT32}
_MAX_NUMBER = 63  # seen fields are kept as bits of a uint64; a higher number takes the generic path
_MAX_DEPTH = 8  # nesting levels followed; a deeper definition takes the generic path


@dataclass(frozen=True)
class ColumnTable:
    """A message definition flattened for the compiled loop.

    Attributes
    ----------
    names : tuple of str
        Dotted field name (``"position.x"``) of each output column.
    actions, targets : ndarray, [nodes, tags], int64
        Per (nested) message and tag (``number << 3 | wire type``): what to do (``_REJECT`` for an unknown
        field or a wire type the definition does not give it) and the column written, or the node of a
        sub-message.  Node 0 is the message itself.
    required : ndarray, [nodes], uint64
        Bit ``k`` set when field ``k`` of the node is required.
    """

    names: tuple[str, ...]
    actions: np.ndarray
    targets: np.ndarray
    required: np.ndarray


_WIRES = {_DOUBLE: FIXED64, _FLOAT: FIXED32, _UINT: VARINT, _INT32: VARINT, _MESSAGE: LENGTH}
# The compiled loop loads floats as they lie in memory; on a big-endian host they go to the generic decoder.
_NATIVE_FLOATS = sys.byteorder == "little"


def column_table(message: Message) -> ColumnTable:
    """Flatten ``message`` (cached: definitions are module constants, built once)."""
    cached = _TABLES.get(id(message))
    if cached is not None and cached[0] is message:
        return cached[1]
    names: list[str] = []
    nodes: list[tuple[Message, list[tuple[int, int, int]]]] = []  # message, [(number, action, target)]

    def add(node_message: Message, prefix: str, depth: int) -> int:
        node = len(nodes)
        entries: list[tuple[int, int, int]] = []
        nodes.append((node_message, entries))
        for number, spec in node_message.fields.items():
            if number > _MAX_NUMBER or spec.repeated:
                continue
            if isinstance(spec.type, Message):
                if depth + 1 < _MAX_DEPTH:
                    entries.append((number, _MESSAGE, add(spec.type, f"{prefix}{spec.name}.", depth + 1)))
            elif spec.type in _CODES:
                if _NATIVE_FLOATS or spec.type not in (DOUBLE, FLOAT):
                    entries.append((number, _CODES[spec.type], len(names)))
                names.append(f"{prefix}{spec.name}")
        return node

    add(message, "", 0)
    tags = (max([number for _, entries in nodes for number, _, _ in entries], default=0) + 1) << 3
    actions = np.zeros((len(nodes), tags), np.int64)
    targets = np.zeros((len(nodes), tags), np.int64)
    required = np.zeros(len(nodes), np.uint64)
    for node, (node_message, entries) in enumerate(nodes):
        held = set()
        for number, action, target in entries:
            tag = number << 3 | _WIRES[action]
            actions[node, tag], targets[node, tag] = action, target
            held.add(number)
        for number in node_message.required:
            # A required field the table does not hold (bytes, a high number) sets bit 0, which no
            # encoding sets (field number 0 is invalid): every element then goes to the generic decoder.
            required[node] |= np.uint64(1 << number if number in held else 1)
    table = ColumnTable(tuple(names), actions, targets, required)
    _TABLES[id(message)] = (message, table)
    return table


_TABLES: dict[int, tuple[Message, ColumnTable]] = {}


@intrinsic
def _load_double(typingctx, data, pos):  # pragma: no cover - compiled
    """The little-endian float64 at byte ``pos`` of a uint8 array: one unaligned load (the host is little-endian)."""

    def codegen(context, builder, signature, args):
        array = context.make_array(signature.args[0])(context, builder, args[0])
        pointer = builder.bitcast(builder.gep(array.data, [args[1]]), ir.DoubleType().as_pointer())
        return builder.load(pointer, align=1)

    return types.float64(data, types.int64), codegen


@intrinsic
def _load_float(typingctx, data, pos):  # pragma: no cover - compiled
    """The little-endian float32 at byte ``pos`` of a uint8 array, widened to float64."""

    def codegen(context, builder, signature, args):
        array = context.make_array(signature.args[0])(context, builder, args[0])
        pointer = builder.bitcast(builder.gep(array.data, [args[1]]), ir.FloatType().as_pointer())
        return builder.fpext(builder.load(pointer, align=1), ir.DoubleType())

    return types.float64(data, types.int64), codegen


@numba.njit(cache=True, nogil=True, inline="always")
def _next_field(data, pos, end):  # pragma: no cover - compiled
    """The top-level field at ``data[pos]``, read as :func:`~zendar_dataset.release.wire.scan` reads it:
    (number, wire type, value or payload offset, payload length, position after it, whether it is whole)."""
    tag = np.int64(data[pos])
    if tag < 0x80:  # one-byte tags and lengths are the rule: skip the general varint loop
        pos += 1
    else:
        tag, pos, complete = read_varint_compiled(data, pos, end)
        if not complete:
            return 0, 0, 0, 0, pos, False
    number = tag >> 3
    wire = tag & 7
    if number == 0:
        return 0, 0, 0, 0, pos, False
    value = pos
    length = 0
    if wire == VARINT or wire == LENGTH:
        if pos < end and data[pos] < 0x80:
            value = np.int64(data[pos])
            pos += 1
        else:
            value, pos, complete = read_varint_compiled(data, pos, end)
            if not complete:
                return 0, 0, 0, 0, pos, False
        if wire == LENGTH:
            length = value
            value = pos
            if length < 0 or length > end - pos:  # negative: a varint past 63 bits
                return 0, 0, 0, 0, pos, False
            pos += length
    elif wire == FIXED64 or wire == FIXED32:
        length = 8 if wire == FIXED64 else 4
        if pos + length > end:
            return 0, 0, 0, 0, pos, False
        pos += length
    else:
        return 0, 0, 0, 0, pos, False
    return number, wire, value, length, pos, True


@numba.njit(cache=True, nogil=True)
def _count_fields(data, start, end, number):  # pragma: no cover - compiled
    """Length-delimited occurrences of field ``number`` and other fields among the top-level fields of
    ``data[start:end]``, and the offset where the encoding breaks (-1 when it does not)."""
    elements = 0
    others = 0
    pos = start
    while pos < end:
        field, wire, _, _, after, whole = _next_field(data, pos, end)
        if not whole:
            return elements, others, pos
        pos = after
        if field == number and wire == LENGTH:
            elements += 1
        else:
            others += 1
    return elements, others, -1


@numba.njit(cache=True, nogil=True)
def _decode_elements(data, start, end, number, offsets, lengths, actions, targets, required, out, ok, others):  # pragma: no cover
    """Decode element ``k`` into row ``out[k]`` (NaN where a field is absent); ``ok[k]`` False where it needs
    the generic decoder (its row is then all NaN).

    One loop for both ways of finding the elements (a call per element would cost more than decoding it):

    - ``number == 0``: element ``k`` is ``data[offsets[k]:offsets[k] + lengths[k]]``.
    - ``number > 0``: the elements are the length-delimited occurrences of field ``number`` among the
      top-level fields of ``data[start:end]``, decoded as the walk reaches them (while their bytes are in
      cache); their payload offsets and lengths are written to ``offsets``/``lengths`` and every other
      field to a row of ``others`` (number, wire type, value or payload offset, payload length).  The
      arrays are sized by :func:`_count_fields`, and the walk stops where it stopped.
    """
    walk = number > 0
    rows = out.shape[0]
    tags = actions.shape[1]
    # The enclosing messages of a nested one: their node, end and fields seen so far.
    stack_nodes = np.empty(_MAX_DEPTH, np.int64)
    stack_ends = np.empty(_MAX_DEPTH, np.int64)
    stack_seen = np.empty(_MAX_DEPTH, np.uint64)
    k = 0
    m = 0
    top = start
    while True:
        if walk:
            if top >= end:
                break
            field, wire, value, length, after, whole = _next_field(data, top, end)
            if not whole:
                break
            top = after
            if field != number or wire != LENGTH:
                others[m, 0], others[m, 1], others[m, 2], others[m, 3] = field, wire, value, length
                m += 1
                continue
            offsets[k], lengths[k] = value, length
            pos = value
            stop = value + length
        else:
            if k >= rows:
                break
            pos = offsets[k]
            stop = pos + lengths[k]
        out[k, :] = np.nan
        node = 0
        seen = np.uint64(0)
        depth = 0
        good = True
        while True:
            if pos == stop:
                if (seen & required[node]) != required[node]:
                    good = False
                    break
                if depth == 0:
                    break
                depth -= 1
                node, stop, seen = stack_nodes[depth], stack_ends[depth], stack_seen[depth]
                continue
            # The tag: one byte for field numbers up to 15, two up to 63.
            tag = np.int64(data[pos])
            pos += 1
            if tag >= 0x80:
                if pos >= stop or data[pos] >= 0x80:
                    good = False
                    break
                tag = (tag & 0x7F) | np.int64(data[pos]) << 7
                pos += 1
            if tag >= tags:
                good = False
                break
            action = actions[node, tag]
            bit = np.uint64(1) << np.uint64(tag >> 3)
            if action == _REJECT or (seen & bit) != 0:
                good = False
                break
            seen |= bit
            target = targets[node, tag]
            if action == _DOUBLE:
                if pos + 8 > stop:
                    good = False
                    break
                out[k, target] = _load_double(data, pos)
                pos += 8
                continue
            if action == _FLOAT:
                if pos + 4 > stop:
                    good = False
                    break
                out[k, target] = _load_float(data, pos)
                pos += 4
                continue
            # A varint: up to 10 bytes; a tenth byte over 1 overflows 64 bits (the generic decoder's job).
            varint = np.uint64(0)
            shift = 0
            while True:
                if pos >= stop or shift > 63:
                    good = False
                    break
                byte = np.int64(data[pos])
                pos += 1
                if shift == 63 and byte > 1:
                    good = False
                    break
                varint |= np.uint64(byte & 0x7F) << np.uint64(shift)
                shift += 7
                if byte < 0x80:
                    break
            if not good:
                break
            if action == _MESSAGE:
                if varint > np.uint64(stop - pos) or depth + 1 >= _MAX_DEPTH:
                    good = False
                    break
                stack_nodes[depth], stack_ends[depth], stack_seen[depth] = node, stop, seen
                depth += 1
                node, stop, seen = target, pos + np.int64(varint), np.uint64(0)
                continue
            if action == _UINT:
                out[k, target] = np.float64(varint)
            else:
                low = np.int64(varint & np.uint64(0xFFFFFFFF))  # negative int32 arrive as 10-byte varints
                out[k, target] = np.float64(low - (1 << 32) if low >= 1 << 31 else low)
        ok[k] = good
        if not good:
            out[k, :] = np.nan
        k += 1


@dataclass
class Columns:
    """Decoded elements as a table: ``values[element, column]`` float64, NaN where a field is absent.

    Attributes
    ----------
    values : ndarray, [n, columns], float64
    names : tuple of str
        Dotted field name (``"position.x"``) of each column: every numeric field the definition reaches
        through singular sub-messages.
    """

    values: np.ndarray
    names: tuple[str, ...]

    def __post_init__(self) -> None:
        self._index = {name: k for k, name in enumerate(self.names)}

    def __contains__(self, name: str) -> bool:
        return name in self._index

    def __getitem__(self, name: str) -> np.ndarray:
        """Column ``name``: ``[n]`` float64, a view."""
        return self.values[:, self._index[name]]

    def block(self, prefix: str, axes: str) -> np.ndarray:
        """``[n, len(axes)]`` float64 of the fields ``prefix.<axis>``: a view when they are adjacent columns
        (a ``Vec3d`` or ``Quaternion`` in field order), else a copy."""
        index = [self._index[f"{prefix}.{axis}"] for axis in axes]
        if index == list(range(index[0], index[0] + len(index))):
            return self.values[:, index[0] : index[0] + len(index)]
        return self.values[:, index]


def decode_repeated_columns(
    element: Message, buf: memoryview, offsets: np.ndarray, lengths: np.ndarray
) -> tuple[Columns, list[int]]:
    """Decode many encodings of one message column-wise (the records of a stream, say).

    Parameters
    ----------
    element
        Their definition.
    buf
        The bytes they index into.
    offsets, lengths : ndarray, [n], int64
        Payload position and size of each element.

    Returns
    -------
    columns : Columns
        Every numeric field, NaN where absent and in the elements handed back.
    slow : list of int
        Indices (increasing) of the elements the caller must decode with
        :func:`~zendar_dataset.release.wire.decode`, which also counts their unknown fields.
    """
    table = column_table(element)
    offsets = np.ascontiguousarray(offsets, np.int64)
    lengths = np.ascontiguousarray(lengths, np.int64)
    values = np.empty((offsets.shape[0], len(table.names)))
    ok = np.empty(offsets.shape[0], np.bool_)
    _decode_elements(
        np.frombuffer(buf, np.uint8), 0, 0, 0, offsets, lengths, table.actions, table.targets, table.required,
        values, ok, np.empty((0, 4), np.int64),
    )
    return Columns(values, table.names), np.flatnonzero(~ok).tolist()


@dataclass
class RepeatedField:
    """A record's repeated sub-message field decoded column-wise, and the record's other fields.

    Attributes
    ----------
    columns : Columns
        One row per occurrence, in record order.
    offsets, lengths : ndarray, [n], int64
        Payload position and size of each occurrence.
    slow : list of int
        Occurrences (increasing) the caller must decode with :func:`~zendar_dataset.release.wire.decode`.
    others : dict
        Field number -> list of ``(wire type, value)`` for every other top-level field: an int for a
        varint, ``(payload offset, length)`` otherwise.
    """

    columns: Columns
    offsets: np.ndarray
    lengths: np.ndarray
    slow: list[int]
    others: dict[int, list]


def decode_repeated_field(element: Message, number: int, buf: memoryview, start: int, end: int) -> RepeatedField:
    """Decode every occurrence of sub-message field ``number`` (of type ``element``) in ``buf[start:end]``.

    The record's top level is walked once to count (sizing the arrays), once to decode: each occurrence is
    decoded as the walk reaches it, while its bytes are in cache.  Raises
    :class:`~zendar_dataset.release.wire.WireError` (the generic decoder's, naming the reason) where the top
    level is malformed.
    """
    table = column_table(element)
    data = np.frombuffer(buf, np.uint8)
    count, other_count, error_at = _count_fields(data, start, end, number)
    if error_at >= 0:
        list(iter_fields(buf, error_at, end))  # raises WireError with the reason
        raise WireError("malformed field", error_at)
    offsets, lengths = np.empty(count, np.int64), np.empty(count, np.int64)
    values, ok = np.empty((count, len(table.names))), np.empty(count, np.bool_)
    other_fields = np.empty((other_count, 4), np.int64)
    _decode_elements(
        data, start, end, number, offsets, lengths, table.actions, table.targets, table.required, values, ok, other_fields
    )
    others: dict[int, list] = {}
    for field, wire, value, length in other_fields.tolist():
        others.setdefault(field, []).append((wire, value if wire == VARINT else (value, length)))
    return RepeatedField(Columns(values, table.names), offsets, lengths, np.flatnonzero(~ok).tolist(), others)
