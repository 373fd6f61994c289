"""Reading one ``.pbs`` stream of the release: framing, message kind, records.

A stream is an optional 8-byte header, then records ``[u32 little-endian
length][payload]`` up to the end of the file, possibly gzip-compressed.
Nothing here trusts the file name for the framing: the header and gzip are
chosen by checking that the chain of ``4 + length`` steps lands exactly on the
end of the (decompressed) bytes.  The message kind and schema generation are
sniffed by decoding the first records strictly with every candidate
definition (``release/messages.py``); the file name only breaks ties.

Example
-------
>>> for record in iter_messages("1739000J1Q_images.pbs"):  # doctest: +SKIP
...     print(record["timestamp"], record["cartesian"]["data"]["rows"])
"""

from __future__ import annotations

import gzip
import mmap
import os
import pathlib
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np

from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.release.messages import Kind, kinds_named
from zendar_dataset.release.wire import WireError, check, decode, scan

HEADER_BYTES = 8
_GZIP_MAGIC = b"\x1f\x8b"
_SNIFF_RECORDS = 16


class UnknownMessageError(ZendarFormatError):
    """A stream whose framing is sound but whose records decode as no known message.

    ``framing`` describes the framing decided (:meth:`Framing.describe`), for the import summary.
    """

    framing: str | None = None


class NoRecordsError(UnknownMessageError):
    """A stream with no non-empty record (an empty file, a header alone, empty records only): nothing
    tells which message it holds, and there is nothing in it to convert."""


@dataclass(frozen=True)
class Framing:
    """How a stream's bytes are laid out.

    Attributes
    ----------
    header_bytes : int
        0 or 8: bytes skipped before the first length prefix.
    gzip : bool
        Whether the file is gzip-compressed (offsets then count decompressed bytes).
    reason : str
        Why this framing was chosen, for the import summary.
    """

    header_bytes: int
    gzip: bool
    reason: str

    def describe(self) -> str:
        header = "8-byte header" if self.header_bytes else "no header"
        return f"{header}{', gzip' if self.gzip else ''} ({self.reason})"


@dataclass(frozen=True)
class Loss:
    """Bytes skipped with ``skip_corrupt``: where, how many and why."""

    offset: int
    size_bytes: int
    reason: str


@dataclass
class _Chain:
    """The records found by following length prefixes from ``start``."""

    start: int
    offsets: list[int] = field(default_factory=list)  # payload offsets
    lengths: list[int] = field(default_factory=list)
    end: int = 0  # where following stopped
    problem: str | None = None  # why it stopped before the end of the data

    @property
    def tiles(self) -> bool:
        return self.problem is None


@numba.njit(cache=True, nogil=True)
def _walk(data: np.ndarray, start: int, offsets: np.ndarray, lengths: np.ndarray):  # pragma: no cover - compiled
    """Follow ``[u32 LE length][payload]`` records from ``start``, filling ``offsets``/``lengths`` while they last.

    Returns (records found, where the walk stopped, the length declared there or -1 at a clean end).
    Compiled: a 200 Hz tracklog holds hundreds of thousands of records and the walk is sequential.
    Called twice, to count and then to fill, so memory follows the record count, not the file size.
    """
    n = data.shape[0]
    count = 0
    pos = start
    while pos + 4 <= n:
        length = np.int64(data[pos]) | np.int64(data[pos + 1]) << 8 | np.int64(data[pos + 2]) << 16 | np.int64(data[pos + 3]) << 24
        if pos + 4 + length > n:
            return count, pos, length
        if count < offsets.shape[0]:
            offsets[count] = pos + 4
            lengths[count] = length
        count += 1
        pos += 4 + length
    return count, pos, np.int64(-1)


def _follow(data: memoryview, start: int) -> _Chain:
    n = len(data)
    raw = np.frombuffer(data, np.uint8)
    count, _, _ = _walk(raw, start, np.empty(0, np.int64), np.empty(0, np.int64))
    offsets, lengths = np.empty(count, np.int64), np.empty(count, np.int64)
    _, end, declared = _walk(raw, start, offsets, lengths)
    chain = _Chain(start, offsets.tolist(), lengths.tolist(), int(end))
    if declared >= 0:
        chain.problem = f"the record at byte offset {end} declares {declared} bytes, only {n - end - 4} are available"
    elif end != n:
        chain.problem = f"{n - end} bytes at byte offset {end} are too few for a length prefix (4 bytes)"
    return chain


def _read_bytes(path: pathlib.Path) -> tuple[memoryview, bool, Any]:
    """The stream's bytes (decompressed when gzip) and whether it was gzip; the third item keeps an mmap alive."""
    with open(path, "rb") as handle:
        magic = handle.read(2)
        if magic == _GZIP_MAGIC:
            handle.seek(0)
            return memoryview(_gunzip(path, handle.read())), True, None
        handle.seek(0, os.SEEK_END)
        if handle.tell() == 0:
            return memoryview(b""), False, None
        mapped = mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ)
    return memoryview(mapped), False, mapped


class _TruncatedGzip(Exception):
    def __init__(self, data: bytes, consumed: int) -> None:
        self.data = data
        self.consumed = consumed


def _gunzip(path: pathlib.Path, raw: bytes) -> bytes:
    try:
        return gzip.decompress(raw)
    except EOFError:
        pass
    except (OSError, zlib.error) as exc:
        raise ZendarFormatError(f"{path}: expected gzip data, found a corrupt gzip stream ({exc})") from None
    # Truncated: keep what decompresses, so the record chain can say where the data ends.
    decompressor = zlib.decompressobj(wbits=31)
    data = decompressor.decompress(raw)
    raise _TruncatedGzip(data, len(raw))


def _first_record_parses(data: memoryview, chain: _Chain, kinds: tuple[Kind, ...]) -> bool:
    for offset, length in zip(chain.offsets, chain.lengths):
        if length == 0:
            continue
        for kind in kinds:
            try:
                check(kind.message, data, offset, offset + length)
                return True
            except WireError:
                continue
        return False
    return True  # only empty records: nothing contradicts this framing


def _choose_framing(data: memoryview, gzipped: bool, kinds: tuple[Kind, ...]) -> tuple[Framing, _Chain]:
    """The framing from the length prefixes alone; the records' content only breaks a tie.

    A chain that tiles the file is sound framing whatever its records hold (an unknown message
    is reported by sniffing, not as corruption). Content is consulted only when both chains tile
    and bytes 0-7 are not zero, or, for a truncated file, to pick the chain to report.
    """
    n = len(data)
    plain = _follow(data, 0)
    if n < HEADER_BYTES:
        return Framing(0, gzipped, "shorter than a header"), plain
    headed = _follow(data, HEADER_BYTES)
    zero_header = bytes(data[:HEADER_BYTES]) == bytes(HEADER_BYTES)
    if plain.tiles and headed.tiles:
        if zero_header:
            return Framing(HEADER_BYTES, gzipped, "lengths tile the file from byte 0 and from byte 8; bytes 0-7 are zero"), headed
        if _first_record_parses(data, headed, kinds) and not _first_record_parses(data, plain, kinds):
            return Framing(HEADER_BYTES, gzipped, "lengths tile the file from byte 0 and 8; only byte 8 parses"), headed
        return Framing(0, gzipped, "lengths tile the file from byte 0 and from byte 8; byte 0 taken"), plain
    if plain.tiles:
        return Framing(0, gzipped, "lengths tile the file from byte 0"), plain
    if headed.tiles:
        return Framing(HEADER_BYTES, gzipped, "lengths tile the file from byte 8"), headed
    # Neither tiles: truncated or corrupt. Keep the framing that reads further with a parsing first record
    # (a chain that broke before its first record proves nothing).
    candidates = [c for c in (headed, plain) if any(c.lengths) and _first_record_parses(data, c, kinds)] or [headed, plain]
    if zero_header and headed in candidates:
        best = headed
    else:
        best = max(candidates, key=lambda c: (c.end, c.start))
    header = best.start
    return Framing(header, gzipped, f"no framing tiles the file; {'byte 8' if header else 'byte 0'} reads furthest"), best


_RESYNC_WINDOW = 16 * 2**20


def _resync(data: memoryview, start: int, kind: Kind) -> int | None:
    """The first offset after ``start`` from which length prefixes tile the rest and the first records decode.

    Candidates are found a window at a time (every offset whose little-endian u32 would end inside
    the data), so memory stays bounded however large the file.
    """
    n = len(data)
    raw_bytes = np.frombuffer(data, np.uint8)
    for window in range(start + 1, n - 4, _RESYNC_WINDOW):
        stop = min(window + _RESYNC_WINDOW, n - 4)
        raw = raw_bytes[window : stop + 3].astype(np.int64)
        count = stop - window
        lengths = raw[:count] | raw[1 : count + 1] << 8 | raw[2 : count + 2] << 16 | raw[3 : count + 3] << 24
        positions = np.arange(window, stop, dtype=np.int64)
        # A resync point starts a non-empty record (runs of zero bytes chain as empty records).
        for pos in positions[(positions + 4 + lengths <= n) & (lengths > 0)]:
            chain = _follow(data, int(pos))
            if not chain.tiles:
                continue
            try:
                for offset, length in zip(chain.offsets[:4], chain.lengths[:4]):
                    if length:
                        check(kind.message, data, offset, offset + length)
            except WireError:
                continue
            return int(pos)
    return None


class ReleaseStream:
    """One ``.pbs`` stream: its framing, message kind and records.

    Parameters
    ----------
    path : path-like
        The stream file (read only, never modified).
    kind : str, optional
        Message name (``"Image"``, ``"TrackerState"``, ``"Position"``, ``"LidarPointsFrame"``,
        ``"RangeDopplerFrame"``, ``"RangeDopplerImageModel"``, ``"CameraIndexRecord"``, or a raw
        kind); sniffed when None.  The schema generation is always sniffed.
    skip_corrupt : bool
        Skip truncated or corrupt stretches (recorded in :attr:`losses`) instead of raising.

    Attributes
    ----------
    framing : Framing
    kind : Kind
        The message kind and generation found.
    losses : list of Loss
        What ``skip_corrupt`` skipped.
    unknown_fields : dict
        ``"<Message>.<number>"`` -> occurrences of fields the kind's definition lacks, skipped while
        decoding (the kind is decided by strict sniffing first).
    notes : list of str
        How the kind was decided, for the import summary.

    Raises
    ------
    ZendarFormatError
        At the byte offset where the file is truncated or corrupt (expected and
        available bytes); :class:`UnknownMessageError` when no known message decodes its records.
    """

    def __init__(self, path: str | os.PathLike, kind: str | None = None, *, skip_corrupt: bool = False) -> None:
        self.path = pathlib.Path(path)
        self.skip_corrupt = skip_corrupt
        self.losses: list[Loss] = []
        self.notes: list[str] = []
        self.unknown_fields: dict[str, int] = {}
        candidates = kinds_named(kind)
        try:
            data, gzipped, self._mapping = _read_bytes(self.path)
        except _TruncatedGzip as truncated:
            data, gzipped, self._mapping = memoryview(truncated.data), True, None
            self._gzip_truncated = truncated.consumed
        else:
            self._gzip_truncated = None
        self.size_bytes = len(data)
        self._data = data
        self.framing, chain = _choose_framing(data, gzipped, candidates)
        try:
            self.kind = self._sniff(chain, candidates)
        except UnknownMessageError as exc:
            if not chain.tiles:
                # Broken framing is the error to report, whatever the records hold.
                self.report_problem(chain.end, len(data) - chain.end, f"truncated or corrupt: {chain.problem}")
            exc.framing = self.framing.describe()
            raise
        self._offsets, self._lengths = self._records(chain)

    def _where(self, offset: int) -> str:
        unit = " (decompressed)" if self.framing.gzip else ""
        return f"{self.path}: byte offset {offset}{unit}"

    def report_problem(self, offset: int, size: int, reason: str) -> None:
        """A truncated or corrupt stretch at ``offset``: raise, or with ``skip_corrupt`` record it as lost."""
        if not self.skip_corrupt:
            raise ZendarFormatError(f"{self._where(offset)}: {reason} (use --skip-corrupt to skip it)")
        self.losses.append(Loss(offset, size, reason))

    def _records(self, chain: _Chain) -> tuple[list[int], list[int]]:
        offsets, lengths = list(chain.offsets), list(chain.lengths)
        if self._gzip_truncated is not None and chain.tiles:
            # The stream stopped on a record boundary: every record read is whole, but what followed
            # in the compressed stream is lost, and how much is unknown.
            self.report_problem(
                len(self._data), 0,
                f"truncated: the gzip stream ends early (after {self._gzip_truncated} compressed bytes), "
                "on a record boundary; the records before it are whole",
            )
        while not chain.tiles:
            reason = chain.problem or "corrupt"
            if self._gzip_truncated is not None:
                reason += f"; the gzip stream ends early (after {self._gzip_truncated} compressed bytes)"
            resume = _resync(self._data, chain.end, self.kind) if self.skip_corrupt else None
            lost = (resume if resume is not None else len(self._data)) - chain.end
            if lost == 0:
                break
            self.report_problem(chain.end, lost, f"truncated or corrupt: {reason}")
            if resume is None:
                break
            chain = _follow(self._data, resume)
            offsets += chain.offsets
            lengths += chain.lengths
        return offsets, lengths

    def _sniff(self, chain: _Chain, candidates: tuple[Kind, ...]) -> Kind:
        alive = list(candidates)
        fields_seen: dict[str, set[int]] = {kind.label: set() for kind in candidates}
        seen = 0
        first_error: tuple[int, str] | None = None
        for offset, length in zip(chain.offsets, chain.lengths):
            if length == 0:
                continue
            survivors = []
            errors = []
            scanned = scan(self._data, offset, offset + length)  # once for every kind tried
            for kind in alive:
                try:
                    fields_seen[kind.label] |= check(kind.message, self._data, offset, offset + length, scanned=scanned)
                    survivors.append(kind)
                except WireError as exc:
                    errors.append(str(exc))
                    if first_error is None:
                        first_error = (offset, str(exc))
            if not survivors and seen:
                # The earlier records already narrowed the kinds; this one is read (or reported) with them.
                self.notes.append(f"the record at byte offset {offset - 4} decodes as none of them strictly ({errors[0]})")
                break
            if not survivors:
                tried = ", ".join(k.label for k in alive)
                detail = f" (first mismatch: {first_error[1]})" if first_error else ""
                raise UnknownMessageError(f"{self._where(offset - 4)}: expected a record of {tried}, found none decodes{detail}")
            alive = survivors
            seen += 1
            if len(alive) == 1 or seen >= _SNIFF_RECORDS:
                break
        if seen == 0:
            if len({kind.name for kind in candidates}) > 1:
                # Taking a default kind would make an empty file a sensor (an empty Image stream a radar).
                raise NoRecordsError(f"{self.path}: no non-empty record, so no message to tell its kind from and nothing to convert")
            kind = candidates[0]
            self.notes.append(f"no non-empty record to sniff; taken as {kind.label}")
            return kind
        if len(alive) > 1:
            # Content first: a kind whose records carry what it is converted from (an Image its image).
            carrying = [k for k in alive if set(k.expects) <= fields_seen[k.label]]
            pool = carrying or alive
            hinted = [k for k in pool if any(h in self.path.name.lower() for h in k.name_hints)]
            chosen = (hinted or pool)[0]
            if len(pool) == 1:
                how = f"only {chosen.label} carries the fields it is converted from"
            elif len(hinted) == 1:
                how = f"the file name chose {chosen.label}"
            else:
                how = f"the release's preference order (2020 first) chose {chosen.label}"
            self.notes.append(f"records decode as {', '.join(k.label for k in alive)}; {how}")
            return chosen
        self.notes.append(f"only {alive[0].label} decodes the first {seen} records")
        return alive[0]

    def __len__(self) -> int:
        return len(self._offsets)

    def records(self) -> Iterator[tuple[int, memoryview, int, int]]:
        """Yield ``(offset, buffer, start, end)`` of every non-empty record, in file order.

        ``offset`` is the byte offset of the record's length prefix.
        """
        for offset, length in zip(self._offsets, self._lengths):
            if length:
                yield offset - 4, self._data, offset, offset + length

    @property
    def empty_records(self) -> int:
        """Records of length 0 in the stream (counted once, however often it is read)."""
        return int(np.count_nonzero(np.asarray(self._lengths, np.int64) == 0))

    @property
    def buffer(self) -> memoryview:
        """The stream's (decompressed) bytes; record offsets index into it."""
        return self._data

    def spans(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every non-empty record at once: ``[n]`` int64 prefix offsets, payload offsets and payload lengths
        (for column-wise decoding of streams of many small records; :attr:`empty_records` counts the others)."""
        lengths = np.asarray(self._lengths, np.int64)
        offsets = np.asarray(self._offsets, np.int64)
        keep = lengths > 0
        return offsets[keep] - 4, offsets[keep], lengths[keep]

    def __iter__(self) -> Iterator[dict[str, Any]]:
        """Decoded records (field name -> value) in file order; corrupt ones raise or are skipped."""
        for offset, data, start, end in self.records():
            try:
                yield decode(self.kind.message, data, start, end, self.unknown_fields)
            except WireError as exc:
                self.report_problem(offset, end - offset, f"record of {self.kind.label} does not decode: {exc}")

    def close(self) -> None:
        """Drop this stream's hold on the file mapping; it is unmapped once no yielded record still views it."""
        self._data = memoryview(b"")
        self._mapping = None

    def __enter__(self) -> "ReleaseStream":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def iter_messages(
    path: str | os.PathLike, kind: str | None = None, *, skip_corrupt: bool = False
) -> Iterator[dict[str, Any]]:
    """Decoded messages of a ``.pbs`` stream, framing, kind and generation detected.

    Parameters
    ----------
    path
        The stream file.
    kind
        Message name to insist on; sniffed when None (see :class:`ReleaseStream`).
    skip_corrupt
        Skip truncated or corrupt stretches instead of raising.

    Yields
    ------
    dict
        Field name -> value; ``bytes`` fields are ``memoryview`` slices valid while iterating.
    """
    stream = ReleaseStream(path, kind, skip_corrupt=skip_corrupt)
    try:
        yield from stream
    finally:
        stream.close()
