"""Submission checks: the evaluator's validator plus the meta rules, every problem at once.

The same function serves ``zendar-leaderboard check`` (offline) and the server, which runs it before
anything is queued. Parsing is strict JSON (orjson): ``NaN``/``Infinity`` literals, numbers that
overflow a double and nesting deeper than 1024 levels are refused by the parser itself, in C,
before any Python recursion could be exhausted; integers of 20 digits or more are refused before
parsing (the parser would round them to a double without a word).
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass, field
from itertools import islice
from typing import Any

import orjson

from zendar_dataset.eval.validation import duplicate_key_problems, iter_frame_set_problems, read_predictions
from zendar_leaderboard.meta import clean_meta, meta_problems

#: Default limit on a submission's size (a 100,000-frame test split takes about 20 MB). Checking an
#: upload takes at most MEMORY_PER_UPLOAD_BYTE times its size, so the server's two checking slots
#: need at most 2 x 40 x 25 MB = 2 GB.
DEFAULT_MAX_BYTES = 25_000_000
#: Peak memory of checking one upload, in bytes per uploaded byte, whatever the upload holds
#: (the densest JSON, ``[{},{},...]``, parses to about 25 bytes per byte; problems past the
#: listed ones are counted, not kept).
MEMORY_PER_UPLOAD_BYTE = 40
#: How a missing frame is explained: every frame of the test split is required.
MISSING_FRAME_HINT = "give [] for a frame without detections: every frame of the test split is required"


@dataclass
class CheckedSubmission:
    """The outcome of checking one submission.

    Attributes
    ----------
    document
        The parsed submission, or None when it has problems (it is not kept for a refusal).
    problems
        Every problem found; empty when the submission may be queued.
    meta
        The known meta keys (empty when ``meta`` has problems).
    sha256
        Hex SHA-256 of the submitted bytes.
    problems_not_listed
        Problems found beyond the ``max_problems`` listed: counted, their text not kept.
    """

    document: Any
    problems: list[str]
    meta: dict = field(default_factory=dict)
    sha256: str = ""
    problems_not_listed: int = 0

    @property
    def ok(self) -> bool:
        return not self.problems and not self.problems_not_listed

    @property
    def problem_count(self) -> int:
        return len(self.problems) + self.problems_not_listed


# A number token (after ':', ',' or '[') with 20 or more integer digits: beyond any 64-bit integer.
# The parser would silently round it to a double; it is refused instead, before parsing.
_HUGE_INTEGER = re.compile(rb"[:,\[]\s*-?\d{20,}")

#: A valid submission holds at most one JSON object or array per this many bytes (a detection
#: takes at least 23, ``{"x":0,"y":0,"score":0}``; a frame at least 8). Denser bodies, such as
#: ``[{},{},...]``, would parse to more than MEMORY_PER_UPLOAD_BYTE times their size.
MIN_BYTES_PER_CONTAINER = 8
#: Bodies smaller than this skip the density rule: whatever they hold, they parse to little.
DENSITY_RULE_FROM_BYTES = 65_536


def parse_json(body: bytes) -> tuple[Any, list[str]]:
    """Strictly parse ``body``; (document, []) or (None, [the reason]).

    The parser's message is kept to its reason and position: it never quotes the body back.
    """
    if len(body) >= DENSITY_RULE_FROM_BYTES:
        containers = body.count(b"{") + body.count(b"[")
        if containers * MIN_BYTES_PER_CONTAINER > len(body):
            # A nesting bomb is dense too: its first bytes already say so, and that is the clearer reason.
            nesting = _nesting_problem(body[:DENSITY_RULE_FROM_BYTES])
            return None, nesting or [
                f"submission: {containers:,} objects and arrays in {len(body):,} bytes, more than one per "
                f"{MIN_BYTES_PER_CONTAINER} bytes; no valid submission is that dense (a detection takes at least 23)"
            ]
    huge = _HUGE_INTEGER.search(body)
    if huge is not None:
        return None, [
            f"submission: the number at character {huge.start() + 1} has more than 19 digits before its "
            "decimal point (beyond any 64-bit integer); write large values with an exponent"
        ]
    try:
        return orjson.loads(body), []
    except orjson.JSONDecodeError as exc:
        return None, [_parse_problem(exc)]


def _parse_problem(exc: orjson.JSONDecodeError) -> str:
    reason = str(exc.msg) if hasattr(exc, "msg") else str(exc)
    if _is_too_deep(reason):
        return f"submission: nested more than 1024 levels deep at character {exc.pos} (a submission needs 4)"
    if "infinity" in reason:
        return f"submission: a number at character {exc.pos} is too large for a double (or NaN/Infinity)"
    return f"submission: not valid JSON at line {exc.lineno} column {exc.colno}: {reason}"[:300]


def _is_too_deep(reason: str) -> bool:
    return "depth limit" in reason or "recursion" in reason


def _nesting_problem(head: bytes) -> list[str]:
    """[the nesting problem] when ``head`` (a body's first bytes) is nested too deeply, else []."""
    try:
        orjson.loads(head)
    except orjson.JSONDecodeError as exc:
        reason = str(exc.msg) if hasattr(exc, "msg") else str(exc)
        return [_parse_problem(exc)] if _is_too_deep(reason) else []
    return []


def check_submission(
    body: bytes, gt_frame_ids: list[str] | None = None, *, max_problems: int | None = None
) -> CheckedSubmission:
    """Check a submission's bytes against the rules.

    Parameters
    ----------
    body
        The submission as uploaded: ``{"meta": {...}, "results": {frame_id: [...]}}``.
    gt_frame_ids
        The test split's frame ids; every one must be in ``results`` and nothing else may be. None
        skips this check (offline, without ground truth).
    max_problems
        List at most this many problems and count the rest (the server); None lists every one.
        Past the cap no problem is kept, so memory stays within a bounded multiple of the body.

    Returns
    -------
    CheckedSubmission
    """
    sha256 = hashlib.sha256(body).hexdigest()
    document, problems = parse_json(body)
    if problems:
        return CheckedSubmission(None, problems, sha256=sha256)
    if not isinstance(document, dict):
        return CheckedSubmission(
            None, [f"submission: expected a JSON object with 'meta' and 'results', got {type(document).__name__}"],
            sha256=sha256,
        )
    problems = [] if "meta" in document else ["submission: missing 'meta' (the method's description)"]
    # A frame id given twice would otherwise lose its first detections without a word.
    problems += duplicate_key_problems(body, document, what="submission")
    if "meta" in document:
        problems += meta_problems(document["meta"])  # a few at most: one per meta field
    checked = read_predictions(document, max_problems=max_problems)
    problems += [p for p in checked.problems if not p.startswith("predictions: 'meta")]
    not_listed = checked.problems_not_listed
    if checked.frame_ids is not None and gt_frame_ids is not None:
        frame_set = iter_frame_set_problems(
            checked.frame_ids, gt_frame_ids, partial=False, missing_hint=MISSING_FRAME_HINT
        )
        room = None if max_problems is None else max(0, max_problems - len(problems))
        problems += islice(frame_set, room)
        not_listed += sum(1 for _ in frame_set)
    if max_problems is not None and len(problems) > max_problems:
        not_listed += len(problems) - max_problems
        del problems[max_problems:]
    if problems or not_listed:
        return CheckedSubmission(None, problems, sha256=sha256, problems_not_listed=not_listed)
    return CheckedSubmission(document, [], clean_meta(document["meta"]), sha256)
