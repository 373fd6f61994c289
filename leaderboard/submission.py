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
from typing import Any

import orjson

from zendar_dataset.eval.validation import frame_set_problems, read_predictions
from zendar_leaderboard.meta import clean_meta, meta_problems

#: Default limit on a submission's size (a 100,000-frame test split takes about 20 MB).
DEFAULT_MAX_BYTES = 200_000_000


@dataclass
class CheckedSubmission:
    """The outcome of checking one submission.

    Attributes
    ----------
    document
        The parsed submission, or None when it could not be parsed.
    problems
        Every problem found; empty when the submission may be queued.
    meta
        The known meta keys (empty when ``meta`` has problems).
    sha256
        Hex SHA-256 of the submitted bytes.
    """

    document: Any
    problems: list[str]
    meta: dict = field(default_factory=dict)
    sha256: str = ""

    @property
    def ok(self) -> bool:
        return not self.problems


# A number token (after ':', ',' or '[') with 20 or more integer digits: beyond any 64-bit integer.
# The parser would silently round it to a double; it is refused instead, before parsing.
_HUGE_INTEGER = re.compile(rb"[:,\[]\s*-?\d{20,}")


def parse_json(body: bytes) -> tuple[Any, list[str]]:
    """Strictly parse ``body``; (document, []) or (None, [the reason]).

    The parser's message is kept to its reason and position: it never quotes the body back.
    """
    huge = _HUGE_INTEGER.search(body)
    if huge is not None:
        return None, [
            f"submission: the number at character {huge.start() + 1} has more than 19 digits before its "
            "decimal point (beyond any 64-bit integer); write large values with an exponent"
        ]
    try:
        return orjson.loads(body), []
    except orjson.JSONDecodeError as exc:
        reason = str(exc.msg) if hasattr(exc, "msg") else str(exc)
        if "depth limit" in reason or "recursion" in reason:
            return None, [f"submission: nested more than 1024 levels deep at character {exc.pos} (a submission needs 4)"]
        if "infinity" in reason:
            return None, [f"submission: a number at character {exc.pos} is too large for a double (or NaN/Infinity)"]
        return None, [f"submission: not valid JSON at line {exc.lineno} column {exc.colno}: {reason}"[:300]]


def check_submission(body: bytes, gt_frame_ids: list[str] | None = None) -> CheckedSubmission:
    """Check a submission's bytes against the rules.

    Parameters
    ----------
    body
        The submission as uploaded: ``{"meta": {...}, "results": {frame_id: [...]}}``.
    gt_frame_ids
        The test split's frame ids; every one must be in ``results`` and nothing else may be. None
        skips this check (offline, without ground truth).

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
    if "meta" in document:
        problems += meta_problems(document["meta"])
    checked = read_predictions(document)
    problems += [p for p in checked.problems if not p.startswith("predictions: 'meta")]
    if checked.frame_ids is not None and gt_frame_ids is not None:
        problems += frame_set_problems(checked.frame_ids, gt_frame_ids, partial=False)
    meta = clean_meta(document["meta"]) if not problems else {}
    return CheckedSubmission(document, problems, meta, sha256)
