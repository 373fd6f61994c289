"""The ranking as data: what ``/api/leaderboard``, the pages and the static export show.

While a round is open each entry shows its score on the public part of the test split; once an
administrator closes the round, entries are ranked by the private part and show both. This module
is the one place that decides which submissions are on the leaderboard, which part of a score is
shown and in what order.

AP (``ap``, ``ap_public``, interval ends in ``ci``, the CSV's ``ap_*`` and ``ci_*`` columns) is a
fraction in [0, 1] rounded to 0.001 = 0.1 AP points, null (an empty CSV cell) for a band without
ground truth; only the HTML pages turn it into percent.
"""

from __future__ import annotations

import csv
import io
import time
from typing import Any

from zendar_dataset.eval.protocol import ALL_BAND
from zendar_leaderboard.scoring import BANDS
from zendar_leaderboard.store import ScoreRow, Store, SubmissionRow


#: Meta keys never shown: the contact address, and the submitter's own ``team`` (``team`` of an
#: entry is the registered name).
PRIVATE_META_KEYS = ("contact", "team")


def iso_utc(unix_s: float) -> str:
    """UNIX seconds as ISO 8601 UTC to the second, e.g. ``2026-12-01T16:55:34Z``."""
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(unix_s))


def shown_part(closed: bool) -> str:
    return "private" if closed else "public"


def shown_score(score: ScoreRow, closed: bool) -> tuple[str, dict]:
    """The part a score is shown for and that part's scores.

    The private part once the round is closed (when it was scored), else the public part (an empty
    dict when that part is empty).
    """
    if closed and score.private:
        return "private", score.private
    return "public", score.public or {}


def entry_dict(submission: SubmissionRow, score: ScoreRow, closed: bool) -> dict[str, Any]:
    """One entry (without its rank) as served by ``/api/leaderboard``."""
    part_name, part = shown_score(score, closed)
    entry: dict[str, Any] = {
        "id": submission.id,
        "method": submission.meta.get("method", ""),
        "team": submission.team,
        "ap": part.get("ap", {band: None for band in BANDS}),
    }
    if part.get("ci"):
        entry["ci"] = part["ci"]
    if closed and score.public:
        entry["ap_public"] = score.public["ap"]
    # The contact address stays with the organisers: a public page would hand it to harvesters.
    # meta.team is only what the submitter typed: the entry's team is the registered one, and a
    # second, unchecked team name next to it could claim to be another team.
    entry["meta"] = {key: value for key, value in submission.meta.items() if key not in PRIVATE_META_KEYS}
    entry["submitted_at"] = iso_utc(submission.submitted_at)
    entry["part"] = part_name
    entry["protocol_version"] = score.protocol_version
    entry["evaluator_version"] = score.evaluator_version
    entry["submission_sha256"] = score.submission_sha256
    entry["gt_sha256"] = score.gt_sha256
    return entry


def entry_parts(store: Store, submission_id: int) -> tuple[dict, dict[str, dict | None]] | None:
    """An entry shown on the leaderboard and its per-part scores (private only once closed).

    None when the submission is not on the leaderboard (missing, hidden or not scored).
    """
    submission = store.submission(submission_id)
    if submission is None or submission.hidden or submission.status != "scored":
        return None
    score = store.score(submission_id)
    closed = store.round_closed()
    entry = entry_dict(submission, score, closed)
    parts = {"public": score.public}
    if closed:
        parts["private"] = score.private
    return entry, parts


def _rank_key(entry: dict, band: str) -> tuple:
    ap = entry["ap"].get(band)
    # Higher AP first; a band without ground truth (None) last; ties: the earlier submission first.
    return (ap is None, -(ap or 0.0), entry["submitted_at"], entry["id"])


def ranked(entries: list[dict], band: str = ALL_BAND) -> list[dict]:
    """Entries sorted by ``band`` (descending AP), each with its ``rank`` (equal AP, equal rank)."""
    ordered = sorted(entries, key=lambda e: _rank_key(e, band))
    previous = object()
    rank = 0
    for position, entry in enumerate(ordered, start=1):
        if entry["ap"].get(band) != previous:
            rank = position
            previous = entry["ap"].get(band)
        entry["rank"] = rank
    return [{"rank": e.pop("rank"), **e} for e in ordered]


def leaderboard(store: Store, band: str = ALL_BAND) -> dict[str, Any]:
    """The whole ranking, sorted by ``band``: ``{"entries": [...], "round": {...}, "sorted_by",
    "generated_at"}``.

    Built from the database on each call; the server keeps one per database generation
    (:class:`zendar_leaderboard.server.RankingCache`).
    """
    closed = store.round_closed()
    entries = [entry_dict(sub, score, closed) for sub, score in store.scored_entries()]
    return {
        "entries": ranked(entries, band),
        "round": {"closed": closed, "shown": shown_part(closed)},
        "sorted_by": band,
        "generated_at": iso_utc(time.time()),
    }


CSV_COLUMNS = (
    ["rank", "method", "team"]
    + [f"ap_{band}" for band in BANDS]
    + [f"ci_{band}_{end}" for band in BANDS for end in ("low", "high")]
    + ["part", "submitted_at", "uses_sar", "uses_camera", "uses_lidar", "uses_supervised",
       "uses_unsupervised_pretraining", "external_data", "runtime_ms", "hardware", "url",
       "submission_sha256", "protocol_version", "gt_sha256"]
)


def _csv_cell(value: Any) -> Any:
    # A cell starting with = + - @ is run as a formula by spreadsheets: quote it as text.
    if isinstance(value, str) and value[:1] in ("=", "+", "-", "@", "\t", "\r"):
        return "'" + value
    return "" if value is None else value


def to_csv(board: dict[str, Any]) -> str:
    """The ranking as CSV text (one row per entry, AP and intervals as fractions in [0, 1])."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for entry in board["entries"]:
        ci = entry.get("ci") or {}
        meta = entry["meta"]
        row = [entry["rank"], entry["method"], entry["team"]]
        row += [entry["ap"].get(band) for band in BANDS]
        row += [(ci.get(band) or [None, None])[k] for band in BANDS for k in (0, 1)]
        row += [entry["part"], entry["submitted_at"]]
        row += [meta.get(key) for key in ("uses_sar", "uses_camera", "uses_lidar", "uses_supervised",
                                          "uses_unsupervised_pretraining", "external_data", "runtime_ms",
                                          "hardware", "url")]
        row += [entry["submission_sha256"], entry["protocol_version"], entry["gt_sha256"]]
        writer.writerow([_csv_cell(v) for v in row])
    return out.getvalue()
