"""A scene's stream files as the importer reads them: opened once with their summary, then decoded record by record.

:func:`open_stream` opens every file of a scene before anything is written (so
every unreadable stream is reported at once); :func:`decoded_records` is the one
loop over a stream's records that every conversion consumes: it counts them,
decodes them, and hands a record that does not decode to the stream (an error,
or with ``--skip-corrupt`` a reported loss), counts the fields the SDK's
definitions do not have (accepted once the stream's kind is decided) and the
records without an optional field their conversion needs (skipped);
:func:`finish_summary` copies what the reading found into the stream's summary.
"""

from __future__ import annotations

import pathlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import TypeVar

from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.release import records as rec
from zendar_dataset.release.messages import RD_MODEL, Kind
from zendar_dataset.release.stream import NoRecordsError, ReleaseStream, UnknownMessageError
from zendar_dataset.release.summary import StreamSummary
from zendar_dataset.release.wire import WireError, decode

T = TypeVar("T")


@dataclass
class OpenedStream:
    """One file of a scene: its stream (None when it is not read further) and its summary."""

    path: pathlib.Path
    stream: ReleaseStream | None
    summary: StreamSummary
    model: rec.RangeDopplerModel | None = None  # for single-message .pb model files
    missing: dict[tuple[str, str], int] = field(default_factory=dict)  # (field, why) -> records skipped


def open_stream(path: pathlib.Path, src: pathlib.Path, skip_corrupt: bool, problems: list[str]) -> OpenedStream:
    """Open ``path`` (under the release folder ``src``) and start its summary.

    A file that is not a stream the importer converts is kept with the reason in its summary; an
    unreadable one (truncated or corrupt, without ``skip_corrupt``) adds its problems to ``problems``.
    """
    summary = StreamSummary(str(path.relative_to(src)) if path != src else path.name)
    if path.name.lower().endswith(".pb"):
        data = memoryview(path.read_bytes())
        try:
            model = rec.rd_model(decode(RD_MODEL, data))
        except (WireError, KeyError) as exc:
            summary.skipped.append(f"single-message file that is not a RangeDopplerImageModel ({exc})")
            return OpenedStream(path, None, summary)
        summary.kind, summary.framing, summary.records = "RangeDopplerImageModel (2020)", "one message, no prefix", 1
        return OpenedStream(path, None, summary, model)
    try:
        stream = ReleaseStream(path, skip_corrupt=skip_corrupt)
    except NoRecordsError as exc:
        summary.framing = exc.framing
        summary.skipped.append(f"empty: {exc}")
        return OpenedStream(path, None, summary)
    except UnknownMessageError as exc:
        # Sound framing, unknown content (a message the release's schemas do not define): not the user's error.
        summary.framing = exc.framing
        summary.skipped.append(f"no known message decodes it: {exc}")
        return OpenedStream(path, None, summary)
    except ZendarFormatError as exc:
        problems.extend(exc.problems)
        return OpenedStream(path, None, summary)
    summary.kind, summary.framing, summary.notes = stream.kind.label, stream.framing.describe(), list(stream.notes)
    if not stream.kind.converted:
        summary.skipped.append(f"{stream.kind.label}: raw acquisition packets are not converted (no decoded product)")
    return OpenedStream(path, stream, summary)


def message(kind: Kind, buf: memoryview, start: int, end: int, unknown: dict[str, int] | None = None) -> dict:
    """One record as field name -> value (the generic decoder; unknown fields counted in ``unknown``)."""
    return decode(kind.message, buf, start, end, unknown)


def decoded_records(
    opened: OpenedStream, convert: Callable[[Kind, memoryview, int, int], T] = message, *, probe: bool = False
) -> Iterator[T]:
    """Every record of a stream that decodes, in file order.

    Parameters
    ----------
    opened
        A stream that :func:`open_stream` opened (its ``stream`` is not None).
    convert
        Decodes one record ``(kind, buffer, start, end, unknown=counts)``; :func:`message` by default, or
        :func:`zendar_dataset.release.records.detections` / :func:`~zendar_dataset.release.records.lidar_sweep`
        (column-wise) / :func:`~zendar_dataset.release.records.sar_frame_record`.
    probe
        A look-ahead pass: records are neither counted nor reported (the writing pass does both).

    Yields
    ------
    What ``convert`` returns.  A record it cannot decode is skipped after
    :meth:`ReleaseStream.report_problem`, which raises :class:`ZendarFormatError`
    (naming the byte offset) or, with ``skip_corrupt``, records the bytes as lost.
    A record without an optional field its conversion needs
    (:class:`~zendar_dataset.release.records.MissingField`) is skipped and counted.
    """
    stream = opened.stream
    unknown = {} if probe else stream.unknown_fields
    for offset, buf, start, end in stream.records():
        opened.summary.records += not probe
        try:
            value = convert(stream.kind, buf, start, end, unknown=unknown)
        except WireError as exc:
            if not probe:
                stream.report_problem(offset, end - offset, f"record does not decode as {stream.kind.label}: {exc}")
            continue
        except rec.MissingField as exc:
            if not probe:
                key = (exc.field, exc.why)
                opened.missing[key] = opened.missing.get(key, 0) + 1
            continue
        yield value


def finish_summary(opened: OpenedStream) -> None:
    """Copy into the stream's summary what reading found: empty records, records without a needed optional
    field, fields the SDK's definitions lack, and the bytes ``skip_corrupt`` skipped."""
    opened.summary.skipped.extend(
        f"{n} records without {name} ({why}): not converted" for (name, why), n in opened.missing.items()
    )
    if opened.stream is not None:
        opened.summary.unknown_fields = dict(sorted(opened.stream.unknown_fields.items()))
        opened.summary.empty_records = opened.stream.empty_records
        opened.summary.lost_bytes = sum(loss.size_bytes for loss in opened.stream.losses)
        opened.summary.skipped.extend(
            f"{loss.size_bytes} bytes at offset {loss.offset}: {loss.reason}" for loss in opened.stream.losses
        )
