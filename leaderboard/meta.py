"""The rules of a submission's ``meta`` object: who made it, how, with which data.

Every problem is collected, never only the first. The checked meta keeps only the known keys, so
nothing else a submitter writes is ever shown. Every text follows the character rules of
:mod:`zendar_leaderboard.names` (no control, invisible formatting or private-use characters, no
stacks of combining marks); the one-line names a page shows (``method``, ``team``, ``hardware``)
are kept normalised, and their length limits count the normalised text.
"""

from __future__ import annotations

import math
import re
from typing import Any

from zendar_leaderboard.names import character_problem, normalised

MAX_METHOD_CHARS = 40

#: Text fields: (name, required, maximum length in characters).
TEXT_FIELDS: tuple[tuple[str, bool, int], ...] = (
    ("method", True, MAX_METHOD_CHARS),
    ("team", True, 100),
    ("contact", True, 200),
    ("description", True, 2000),
    ("url", False, 500),
    ("hardware", True, 200),
)

BOOLEAN_FIELDS = (
    "uses_unsupervised_pretraining",
    "uses_supervised",
    "uses_sar",
    "uses_camera",
    "uses_lidar",
    "external_data",
)

#: runtime_ms must lie in [0, MAX_RUNTIME_MS] (a day per frame is already beyond any use).
MAX_RUNTIME_MS = 86_400_000.0

META_KEYS = tuple(name for name, _, _ in TEXT_FIELDS) + BOOLEAN_FIELDS + ("runtime_ms",)

#: One-line names shown on the pages: stored normalised (NFKC, single spaces, stripped).
NORMALISED_FIELDS = ("method", "team", "hardware")

#: The one text that may hold line breaks and tabs.
MULTILINE_FIELDS = ("description",)


def _type_name(value: Any) -> str:
    return "null" if value is None else type(value).__name__


def meta_problems(meta: Any) -> list[str]:
    """Every violation of the meta rules.

    Parameters
    ----------
    meta
        The submission's ``meta`` value (anything parsed from JSON).

    Returns
    -------
    list of str
        Empty when ``meta`` is valid; each entry names the field.
    """
    if not isinstance(meta, dict):
        return [f"submission: 'meta' must be an object with {', '.join(META_KEYS)}, got {_type_name(meta)}"]
    problems = []
    for name, required, max_chars in TEXT_FIELDS:
        if name not in meta:
            if required:
                problems.append(f"meta: missing {name!r} (a string of at most {max_chars} characters)")
            continue
        value = meta[name]
        if not isinstance(value, str):
            problems.append(f"meta: {name!r} must be a string, got {_type_name(value)}")
            continue
        # Normalising can lengthen a text (one compatibility character may stand for many).
        shown = normalised(value) if name in NORMALISED_FIELDS else value
        if len(shown) > max_chars:
            problems.append(f"meta: {name!r} has {len(shown)} characters, more than the limit of {max_chars}")
        if name in ("method", "team", "contact", "hardware") and not value.strip():
            problems.append(f"meta: {name!r} is empty")
        character = character_problem(value, multiline=name in MULTILINE_FIELDS)
        if character is not None:
            problems.append(f"meta: {name!r} {character}")
        if name == "url" and not re.match(r"https?://[^\s]+$", value):
            problems.append(f"meta: 'url' must start with http:// or https:// and contain no spaces, got {value[:60]!r}")
    for name in BOOLEAN_FIELDS:
        if name not in meta:
            problems.append(f"meta: missing {name!r} (true or false)")
        elif not isinstance(meta[name], bool):
            problems.append(f"meta: {name!r} must be true or false, got {_type_name(meta[name])}")
    if "runtime_ms" not in meta:
        problems.append("meta: missing 'runtime_ms' (milliseconds per frame, a number)")
    else:
        runtime_ms = meta["runtime_ms"]
        if type(runtime_ms) not in (int, float):  # bool is refused too
            problems.append(f"meta: 'runtime_ms' must be a number, got {_type_name(runtime_ms)}")
        elif not (math.isfinite(runtime_ms) and 0 <= runtime_ms <= MAX_RUNTIME_MS):
            problems.append(f"meta: 'runtime_ms' must lie in [0, {MAX_RUNTIME_MS:.0f}], got {runtime_ms!r}"[:160])
    return problems


def clean_meta(meta: dict) -> dict:
    """The known keys of a valid ``meta``, in a fixed order (``url`` only when given), with the
    names of :data:`NORMALISED_FIELDS` normalised."""
    return {
        name: normalised(meta[name]) if name in NORMALISED_FIELDS else meta[name]
        for name in META_KEYS
        if name in meta
    }
