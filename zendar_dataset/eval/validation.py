"""Load and check predictions and ground-truth files, reporting every problem at once.

Valid files take a fast path (whole-column type checks and one numpy conversion); only when that
path finds something wrong does a per-detection scan run, so that each problem can be named by
frame id and detection index.
"""

from __future__ import annotations

import contextlib
import gc
import json
import math
import os
import re
import sys
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from itertools import chain
from pathlib import Path
from typing import Any

import numpy as np
import orjson

from zendar_dataset.eval.protocol import DEFAULT_MAX_BYTES, MAX_DETECTIONS_PER_FRAME

PREDICTION_REQUIRED = ("x", "y", "score")
PREDICTION_OPTIONAL = ("length", "width", "yaw", "vx", "vy")
GROUND_TRUTH_REQUIRED = ("x", "y")

_NUMBER_TYPES = frozenset({float, int})


def _is_number_type(kind: type) -> bool:
    """int, float and numpy's integer and floating scalars (an API caller's values); never bool."""
    return kind in _NUMBER_TYPES or (issubclass(kind, (np.integer, np.floating)) and kind is not np.bool_)


@dataclass(frozen=True)
class _LongInteger:
    """An integer literal longer than Python converts (4,300 digits by default), kept as its length.

    Parsing goes on past it, so that the checks can name the frame, detection or meta field that
    holds it, among every other problem.
    """

    digits: int


def _parse_int(text: str) -> int | _LongInteger:
    """``json``'s integer conversion, with a :class:`_LongInteger` where ``int`` refuses the length."""
    try:
        return int(text)
    except ValueError:
        return _LongInteger(len(text.lstrip("-")))


@dataclass(frozen=True)
class DetectionTable:
    """Detections of many frames as flat columns.

    Attributes
    ----------
    frame_ids
        Frame ids ``"<scene_id>/<timestamp_ns>"`` in file order, length F.
    offsets
        int64 (F + 1,): detections of frame f are rows ``offsets[f]:offsets[f + 1]``, in list order.
    x_m, y_m
        float64 (N,), ego frame, metres.
    score
        float64 (N,) for predictions, None for ground truth.
    """

    frame_ids: list[str]
    offsets: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    score: np.ndarray | None = None

    def __post_init__(self) -> None:
        n_frames = len(self.frame_ids)
        if self.offsets.shape != (n_frames + 1,):
            raise ValueError(f"offsets must have shape ({n_frames + 1},), got {self.offsets.shape}")
        n = int(self.offsets[-1])
        for name in ("x_m", "y_m") + (("score",) if self.score is not None else ()):
            if getattr(self, name).shape != (n,):
                raise ValueError(f"{name} must have shape ({n},), got {getattr(self, name).shape}")

    @property
    def counts(self) -> np.ndarray:
        """int64 (F,): detections per frame."""
        return np.diff(self.offsets)

    @property
    def frame_of_row(self) -> np.ndarray:
        """int64 (N,): the frame index of every detection row."""
        return np.repeat(np.arange(len(self.frame_ids), dtype=np.int64), self.counts)


@dataclass
class CheckedInput:
    """The outcome of checking one input file.

    Attributes
    ----------
    table
        The detections, or None when any problem was found.
    frame_ids
        Frame ids read (even when detections have problems, so that frame sets can still be
        compared), or None when the frame mapping itself could not be read.
    problems
        Every problem found, each naming its frame and detection index.
    meta
        The predictions' ``meta`` object (empty for ground truth).
    split
        The split named by a ground-truth source, when known.
    problems_not_listed
        Problems found beyond the ``max_problems`` asked for: counted, their text not kept.
    """

    table: DetectionTable | None
    frame_ids: list[str] | None
    problems: list[str]
    meta: dict = field(default_factory=dict)
    split: str | None = None
    problems_not_listed: int = 0


class _Problems:
    """Problems in the order found: the first ``max_problems`` kept, the rest only counted.

    A hostile input can hold millions of faults in a few bytes each; past the cap each message is
    dropped as soon as it is made, so the memory kept does not grow with the input.
    """

    def __init__(self, max_problems: int | None) -> None:
        self.max_problems = max_problems
        self.listed: list[str] = []
        self.not_listed = 0

    def add(self, problem: str) -> None:
        if self.max_problems is None or len(self.listed) < self.max_problems:
            self.listed.append(problem)
        else:
            self.not_listed += 1

    def extend(self, problems: Iterable[str]) -> None:
        for problem in problems:
            self.add(problem)


@contextlib.contextmanager
def _collector_paused():
    # A parsed JSON document holds no reference cycles, so the collections that millions of new
    # dicts trigger while parsing find nothing; pausing them saves about a third of the parse.
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


def load_document(
    source: Any, *, what: str, max_bytes: int = DEFAULT_MAX_BYTES
) -> tuple[Any, list[str]]:
    """Read a JSON document from a path, or pass through an already-loaded object.

    The size limit is checked before reading. Python's ``json`` accepts the non-standard
    literals NaN and Infinity; they are let through here and reported as non-finite values,
    with their location, by the column checks.

    Parameters
    ----------
    source
        A path (str or os.PathLike) or an already-parsed object.
    what
        "predictions" or "ground truth", used in messages.
    max_bytes
        Files larger than this are refused unread.

    Returns
    -------
    (document, problems)
        ``document`` is None when it could not be read. A readable file's keys given twice in one
        object are ``problems`` too (:func:`duplicate_key_problems`), its document still returned
        (each such key's last value, as JSON parsers keep it) so that the rest can be checked.
    """
    if not isinstance(source, (str, os.PathLike)):
        return source, []
    path = Path(source)
    if not path.exists():
        return None, [f"{what} file {str(path)!r} does not exist"]
    if not path.is_file():
        return None, [f"{what} path {str(path)!r} is not a file"]
    size = path.stat().st_size
    if size > max_bytes:
        return None, [
            f"{what} file {str(path)!r} is {size:,} bytes, over the limit of {max_bytes:,} bytes "
            "(raise the limit with --max-bytes if this is intended)"
        ]
    raw = path.read_bytes()
    document, problems = _parse(raw, f"{what} file {str(path)!r}", what)
    if problems:
        return None, problems
    return document, duplicate_key_problems(raw, document, what=what)


def _parse(raw: bytes, named: str, what: str) -> tuple[Any, list[str]]:
    """(document, []) or (None, [why ``raw`` is not a JSON document]); ``named`` names the file."""
    try:
        # orjson parses large prediction files several times faster than the standard library.
        with _collector_paused():
            return orjson.loads(raw), []
    except orjson.JSONDecodeError:
        # Strict JSON refused it: NaN/Infinity literals, huge integers, lone surrogates or broken
        # text. The standard parser accepts the first three (each reported with its location by
        # the checks) and gives line/column positions for text that is really broken.
        pass
    try:
        with _collector_paused():
            return json.loads(raw, parse_int=_parse_int), []
    except UnicodeDecodeError as exc:
        return None, [f"{named} is not JSON text: {exc}"]
    except json.JSONDecodeError as exc:
        return None, [f"{named} is not valid JSON: {exc}"]
    except RecursionError:
        return None, [f"{named} is nested too deeply to be a {what} file"]


#: The member of each kind of document that maps frame ids to detections.
_FRAMES_MEMBER = {"predictions": "results", "submission": "results", "ground truth": "frames"}


def duplicate_key_problems(raw: bytes, document: Any, *, what: str) -> list[str]:
    """Every key given more than once in one object of the JSON text ``raw``, each named with where.

    JSON parsers keep a repeated key's last value without a word, so a frame given twice would
    silently lose its first detections. Proving there is no repeat is cheap: outside strings, a
    ``:`` follows each key and nothing else, so the count of ``:`` in ``raw`` less those inside the
    document's strings bounds the keys written from above; the keys the parsed ``document`` holds
    bound them from below; equal bounds leave no room for a repeat. Only when they differ is
    ``raw`` parsed again, slowly, to name each repeat.

    Parameters
    ----------
    raw
        The file's bytes.
    document
        ``raw`` parsed.
    what
        "predictions" or "ground truth", used in messages.

    Returns
    -------
    list of str
        One problem per repeated key, object by object (an object before those inside it).
    """
    keys, colons_in_strings = _keys_and_colons(document)
    if _keys_written_at_most(raw, colons_in_strings) == keys:
        return []
    return _repeated_key_problems(raw, what)


def _keys_and_colons(document: Any) -> tuple[int, int]:
    """At most the keys of ``document``'s objects, and at most the ``:`` in its strings.

    A frame mapping's detections are counted at C speed without looking inside them: the keys of
    objects nested in a detection and the ``:`` in its strings are left out (both err on the side
    of the slow exact pass).
    """
    keys = colons = 0
    stack = [document]
    while stack:
        value = stack.pop()
        if isinstance(value, str):
            colons += value.count(":")
        elif isinstance(value, dict):
            keys += len(value)
            colons += "".join(value).count(":")  # parsed from JSON text: every key is a string
            try:
                keys += sum(map(dict.__len__, chain.from_iterable(map(list.__iter__, value.values()))))
            except TypeError:  # not a frame mapping (meta, or a malformed frame): walk it
                stack.extend(value.values())
        elif isinstance(value, list):
            stack.extend(value)
    return keys, colons


def _keys_written_at_most(raw: bytes, colons_in_strings: int) -> int:
    r"""An upper bound of the keys written in ``raw``: its ``:`` less those known to be in strings.

    ``colons_in_strings`` counts the ``:`` of parsed strings, which may each have been written as
    the escape ``\u003a``: every such escape written is allowed for.
    """
    colons = int(np.count_nonzero(np.frombuffer(raw, dtype=np.uint8) == ord(":")))  # twice bytes.count's speed
    if colons_in_strings and json.detect_encoding(raw).startswith("utf-8"):
        # Counting every escape \u0030 to \u003f overcounts, which is safe; most files hold no "\" at all.
        escapes = raw.count(b"\\u003") if b"\\" in raw else 0
        colons -= max(0, colons_in_strings - escapes)
    return colons


class _Object(dict):
    """A parsed JSON object that remembers the keys its text gave more than once, and how often."""

    repeated: dict[str, int]


def _object_of_pairs(pairs: list[tuple[str, Any]]) -> _Object:
    # Like json's own objects, the last value of a repeated key is kept.
    value = _Object(pairs)
    value.repeated = {}
    if len(value) < len(pairs):
        seen: set[str] = set()
        for key, _ in pairs:
            if key in seen:
                value.repeated[key] = value.repeated.get(key, 1) + 1
            seen.add(key)
    return value


def _repeated_key_problems(raw: bytes, what: str) -> list[str]:
    """The exact pass of :func:`duplicate_key_problems`: ``raw`` parsed again, every repeat named."""
    try:
        with _collector_paused():
            document = json.loads(raw, object_pairs_hook=_object_of_pairs, parse_int=_parse_int)
    except RecursionError:  # orjson read deeper than Python's parser can: the repeats cannot be named
        return [f"{what}: a key is given more than once in an object nested too deeply to name it"]
    problems = []
    stack: list[tuple[tuple[str | int, ...], Any]] = [((), document)]
    while stack:
        path, value = stack.pop()
        if isinstance(value, _Object):
            problems.extend(_repeat_problem(what, path, key, times) for key, times in value.repeated.items())
            stack.extend(((*path, key), item) for key, item in reversed(value.items()))
        elif isinstance(value, list):
            stack.extend(((*path, index), item) for index, item in reversed(list(enumerate(value))))
    return problems


def _repeat_problem(what: str, path: tuple[str | int, ...], key: str, times: int) -> str:
    """The message for ``key`` given ``times`` times in the object at ``path``."""
    frames = _FRAMES_MEMBER.get(what)
    if path == (frames,):
        return f"{what}: frame {key!r} is given {times} times in {frames!r} (a JSON reader keeps only the last)"
    if len(path) == 3 and path[0] == frames and isinstance(path[2], int):
        return f"{what} frame {path[1]!r} detection {path[2]}: {key!r} is given {times} times"
    where = "at the top level" if not path else f"in {_json_path(path)!r}"
    return f"{what}: key {key!r} is given {times} times {where}"


def _json_path(path: tuple[str | int, ...]) -> str:
    """``("meta", "tags", 2)`` as ``meta.tags[2]``."""
    return "".join(f"[{part}]" if isinstance(part, int) else f".{part}" for part in path).lstrip(".")


def _type_name(value: Any) -> str:
    return "null" if value is None else type(value).__name__


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _number_problem(value: Any) -> str | None:
    """Why ``value`` is not a finite JSON number, or None when it is one."""
    if isinstance(value, _LongInteger):
        return f"holds a number that cannot be read (an integer of {value.digits:,} digits; the limit is {sys.get_int_max_str_digits()})"
    if not _is_number_type(type(value)):  # bool is a subclass of int and is refused here
        return f"must be a number, got {_type_name(value)} {_short(value)}"
    try:
        as_float = float(value)
    except OverflowError:
        return f"is too large for a float ({_short(value)})"
    if not math.isfinite(as_float):
        return f"is not finite ({value})"
    return None


#: A code point of UTF-16's surrogate range: in a parsed string, always one of a broken pair.
_SURROGATE = re.compile("[\ud800-\udfff]")


def _text_problem(text: str) -> str | None:
    r"""Why ``text`` cannot be printed or written as UTF-8, or None when it can.

    Python's ``json`` reads the escape of half a surrogate pair (``"\ud800"``) into a string that
    no UTF-8 output can hold; orjson, like strict JSON readers, refuses the file outright.
    """
    lone = _SURROGATE.search(text)
    if lone is None:
        return None
    return f"is not valid Unicode text: it holds a lone surrogate ({lone.group()!r}) at character {lone.start() + 1}"


def _meta_value_problem(value: Any) -> str | None:
    """Why a scalar of ``meta`` cannot be printed or written to metrics.json, or None."""
    if isinstance(value, str):
        return _text_problem(value)
    if isinstance(value, _LongInteger):
        return f"is an integer of {value.digits:,} digits, too long to read"
    if isinstance(value, float) and not math.isfinite(value):
        return f"is not finite ({value})"
    if value is None or isinstance(value, (bool, int, float)):
        return None
    return f"is not a JSON value (got {_type_name(value)})"


def _meta_problems(meta: dict) -> list[str]:
    """Every value (and key) of ``meta``, at any depth, that its printing or metrics.json, which
    copies it, could not hold: text that is not Unicode, non-finite numbers, non-JSON values."""
    problems = []
    stack: list[tuple[str, Any]] = [("meta", meta)]
    while stack:
        path, value = stack.pop()
        if isinstance(value, dict):
            for key in value:
                # json.dumps writes numbers, booleans and None as keys too (as text), as metrics.json does.
                reason = _text_problem(key) if isinstance(key, str) else (
                    None if key is None or isinstance(key, (bool, int, float)) and math.isfinite(key) else "is not a string")
                if reason:
                    problems.append(f"predictions: a key of {path!r} ({_short(key)}) {reason}")
            stack.extend((f"{path}.{key}", item) for key, item in reversed(value.items()))
        elif isinstance(value, (list, tuple)):  # a tuple is written as a JSON array
            stack.extend((f"{path}[{index}]", item) for index, item in reversed(list(enumerate(value))))
        else:
            reason = _meta_value_problem(value)
            if reason:
                problems.append(f"predictions: {path!r} {reason}")
    return problems


def _detection_problems(
    who: str, frame_id: str, index: int, detection: Any, required: tuple[str, ...], optional: tuple[str, ...]
) -> list[str]:
    where = f"{who} frame {frame_id!r} detection {index}"
    if not isinstance(detection, dict):
        return [f"{where}: expected an object with {', '.join(required)}, got {_type_name(detection)}"]
    problems = []
    for key in required:
        if key not in detection:
            problems.append(f"{where}: missing {key!r}")
            continue
        reason = _number_problem(detection[key])
        if reason:
            problems.append(f"{where}: {key!r} {reason}")
    for key in optional:
        if key in detection:
            reason = _number_problem(detection[key])
            if reason:
                problems.append(f"{where}: {key!r} {reason}")
    return problems


def _number_column(values: list[Any]) -> np.ndarray | None:
    """float64 (N,) of ``values``, or None if any is not an int or float (bool is refused) or overflows."""
    if not all(map(_is_number_type, set(map(type, values)))):
        return None
    try:
        return np.fromiter(values, dtype=np.float64, count=len(values))
    except OverflowError:
        return None


def _columns(flat: list[Any], required: tuple[str, ...]) -> dict[str, np.ndarray] | None:
    """Fast path: the required columns as float64, or None if any value is missing or not a number."""
    columns = {}
    for key in required:
        try:
            column = _number_column([detection[key] for detection in flat])
        except (KeyError, TypeError, IndexError):
            return None
        if column is None:
            return None
        columns[key] = column
    return columns


def _optional_suspects(flat: list[dict], optional: tuple[str, ...]) -> np.ndarray:
    """bool (N,): detections whose optional fields need the per-detection check."""
    suspect = np.zeros(len(flat), dtype=bool)
    for key in optional:
        column = _number_column([detection.get(key, 0.0) for detection in flat])  # absent is fine
        if column is None:  # a value of the wrong type: let the per-detection check name it
            suspect |= np.fromiter((key in d for d in flat), dtype=bool, count=len(flat))
        else:
            suspect |= ~np.isfinite(column)
    return suspect


def _frame_problems(
    frames: dict, who: str, max_per_frame: int | None, problems: _Problems
) -> tuple[list[str], list[str], list[list]]:
    """Per-frame checks into ``problems``: (all string frame ids, ids of frames with a list, those lists)."""
    all_frame_ids: list[str] = []
    frame_ids: list[str] = []
    lists: list[list] = []
    for frame_id, detections in frames.items():
        if not isinstance(frame_id, str):
            problems.add(f"{who} frame id {_short(frame_id)} is not a string")
            continue
        all_frame_ids.append(frame_id)
        if not isinstance(detections, list):
            problems.add(
                f"{who} frame {frame_id!r}: expected a list of detections, got {_type_name(detections)}"
            )
            continue
        if max_per_frame is not None and len(detections) > max_per_frame:
            problems.add(
                f"{who} frame {frame_id!r}: {len(detections)} detections, more than the limit of "
                f"{max_per_frame} per frame"
            )
        frame_ids.append(frame_id)
        lists.append(detections)
    return all_frame_ids, frame_ids, lists


#: Suspect detections are named this many at a time: one Python int per suspect for millions of
#: them would cost more memory than the input itself.
_SUSPECT_CHUNK = 65_536


def _suspect_problems(
    who: str,
    frame_ids: list[str],
    offsets: np.ndarray,
    flat: list[Any],
    suspects: np.ndarray | range,
    required: tuple[str, ...],
    optional: tuple[str, ...],
    problems: _Problems,
) -> None:
    """The problems of the detections at the flat rows ``suspects``, into ``problems``."""
    for start in range(0, len(suspects), _SUSPECT_CHUNK):
        rows = np.asarray(suspects[start:start + _SUSPECT_CHUNK], dtype=np.int64)
        frame_of = np.searchsorted(offsets, rows, side="right") - 1
        for row, frame in zip(rows.tolist(), frame_of.tolist()):
            index = row - int(offsets[frame])
            problems.extend(_detection_problems(who, frame_ids[frame], index, flat[row], required, optional))


def read_frames(
    frames: dict,
    *,
    who: str,
    required: tuple[str, ...],
    optional: tuple[str, ...] = (),
    max_per_frame: int | None = None,
    max_problems: int | None = None,
) -> CheckedInput:
    """Check a ``{frame_id: [detection, ...]}`` mapping and turn it into a :class:`DetectionTable`.

    Parameters
    ----------
    frames
        The mapping (already known to be a dict).
    who
        "predictions" or "ground truth", used in messages.
    required
        Keys every detection must carry as finite numbers (``x``, ``y`` and, for predictions, ``score``).
    optional
        Keys that, when present, must be finite numbers.
    max_per_frame
        Limit on detections per frame, or None.
    max_problems
        Keep the text of at most this many problems and only count the rest
        (``problems_not_listed``); None keeps every one.

    Returns
    -------
    CheckedInput
    """
    problems = _Problems(max_problems)
    frame_ids = all_frame_ids = list(frames)
    lists = list(frames.values())
    frames_ok = set(map(type, frame_ids)) <= {str} and set(map(type, lists)) <= {list}
    counts = np.fromiter(map(len, lists), dtype=np.int64, count=len(lists)) if frames_ok else None
    if counts is None or (max_per_frame is not None and len(counts) and counts.max() > max_per_frame):
        # Something is wrong with the frames themselves: find and name each.
        all_frame_ids, frame_ids, lists = _frame_problems(frames, who, max_per_frame, problems)
        counts = np.fromiter(map(len, lists), dtype=np.int64, count=len(lists))
    offsets = np.zeros(len(lists) + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    flat = list(chain.from_iterable(lists))
    columns = _columns(flat, required)

    suspects: np.ndarray | range
    if columns is None:
        suspects = range(len(flat))
    else:
        finite = np.ones(len(flat), dtype=bool)
        for values in columns.values():
            finite &= np.isfinite(values)
        suspect = ~finite
        # Detections with more keys than the required ones may carry optional fields to check.
        if optional and set(map(len, flat)) - {len(required)}:
            suspect |= _optional_suspects(flat, optional)
        suspects = np.flatnonzero(suspect)

    _suspect_problems(who, frame_ids, offsets, flat, suspects, required, optional, problems)

    if problems.listed or problems.not_listed or columns is None:
        return CheckedInput(None, all_frame_ids, problems.listed, problems_not_listed=problems.not_listed)
    table = DetectionTable(
        frame_ids=frame_ids,
        offsets=offsets,
        x_m=columns["x"],
        y_m=columns["y"],
        score=columns.get("score"),
    )
    return CheckedInput(table, all_frame_ids, [])


def read_predictions(document: Any, *, max_problems: int | None = None) -> CheckedInput:
    """Check a predictions document ``{"meta": {...}, "results": {frame_id: [...]}}``.

    ``max_problems`` keeps the text of at most that many problems of the detections and frames and
    counts the rest in ``problems_not_listed`` (None: every one, as ``zendar-eval`` reports them).
    """
    if not isinstance(document, dict):
        return CheckedInput(None, None, [
            "predictions: expected a JSON object with 'meta' and 'results', "
            f"got {_type_name(document)}"
        ])
    problems = []
    meta = document.get("meta", {})
    if not isinstance(meta, dict):
        problems.append(f"predictions: 'meta' must be an object, got {_type_name(meta)}")
        meta = {}
    else:
        if "method" in meta and not isinstance(meta["method"], str):
            problems.append(f"predictions: 'meta.method' must be a string, got {_type_name(meta['method'])}")
        problems += _meta_problems(meta)
    if "results" not in document:
        problems.append(
            "predictions: missing 'results' (an object mapping frame id to a list of detections)"
        )
        return CheckedInput(None, None, problems, meta)
    results = document["results"]
    if not isinstance(results, dict):
        problems.append(
            f"predictions: 'results' must be an object mapping frame id to a list of detections, "
            f"got {_type_name(results)}"
        )
        return CheckedInput(None, None, problems, meta)
    checked = read_frames(
        results,
        who="predictions",
        required=PREDICTION_REQUIRED,
        optional=PREDICTION_OPTIONAL,
        max_per_frame=MAX_DETECTIONS_PER_FRAME,
        max_problems=max_problems,
    )
    checked.problems[:0] = problems
    checked.meta = meta
    if checked.problems or checked.problems_not_listed:
        checked.table = None
    return checked


def read_ground_truth_document(document: Any) -> CheckedInput:
    """Check a ground-truth document ``{"frames": {frame_id: [{"x", "y", ...}]}}``.

    The document's ``"split"`` member, when it is a string, is reported as the split.
    """
    if not isinstance(document, dict):
        return CheckedInput(None, None, [
            f"ground truth: expected a JSON object with 'frames', got {_type_name(document)}"
        ])
    split = document.get("split") if isinstance(document.get("split"), str) else None
    problems = []
    if split is not None and _text_problem(split):  # the split is printed and written to metrics.json
        problems.append(f"ground truth: 'split' {_text_problem(split)}")
        split = None
    if "frames" not in document:
        problems.append("ground truth: missing 'frames' (an object mapping frame id to a list of objects)")
        return CheckedInput(None, None, problems, split=split)
    frames = document["frames"]
    if not isinstance(frames, dict):
        problems.append(
            f"ground truth: 'frames' must be an object mapping frame id to a list, got {_type_name(frames)}"
        )
        return CheckedInput(None, None, problems, split=split)
    checked = read_frames(frames, who="ground truth", required=GROUND_TRUTH_REQUIRED)
    checked.split = split
    if problems:
        checked.problems[:0] = problems
        checked.table = None
    return checked


#: How a missing frame is explained to ``zendar-eval``'s users.
MISSING_FRAME_HINT = "give [] for a frame without detections, or use --partial to evaluate a subset"


def frame_set_problems(pred_frame_ids: list[str], gt_frame_ids: list[str], *, partial: bool) -> list[str]:
    """Frames that are in one input and not in the other.

    Every ground-truth frame must appear in the predictions (an empty list says "no detections")
    unless ``partial``; every prediction frame must be a ground-truth frame.
    """
    return list(iter_frame_set_problems(pred_frame_ids, gt_frame_ids, partial=partial))


def iter_frame_set_problems(
    pred_frame_ids: list[str], gt_frame_ids: list[str], *, partial: bool, missing_hint: str = MISSING_FRAME_HINT
) -> Iterator[str]:
    """:func:`frame_set_problems` one at a time (a caller may keep only the first few), a missing
    frame explained by ``missing_hint``."""
    gt_ids = set(gt_frame_ids)
    for frame_id in pred_frame_ids:
        if frame_id not in gt_ids:
            hint = "" if "/" in frame_id else " (frame ids are '<scene_id>/<timestamp_ns>')"
            yield f"predictions frame {frame_id!r} is not in the ground truth{hint}"
    if not partial:
        pred_ids = set(pred_frame_ids)
        for frame_id in gt_frame_ids:
            if frame_id not in pred_ids:
                yield f"ground truth frame {frame_id!r} is missing from predictions 'results' ({missing_hint})"
