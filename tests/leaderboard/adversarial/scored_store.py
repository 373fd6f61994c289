"""A leaderboard database with scored entries written directly (no scorer), for page and export tests."""

from __future__ import annotations

import hashlib
from pathlib import Path

from tests.leaderboard.conftest import meta
from zendar_leaderboard.scoring import BANDS
from zendar_leaderboard.store import Store

#: A perfect curve as the scorer stores it: every detection at one score, so one point.
PERFECT_CURVE = {"recall": [1.0], "precision": [1.0], "precision_envelope": [1.0]}


def part_score(ap: dict[str, float | None], curve: dict | None = None) -> dict:
    """One part's stored score with AP per band (fractions), intervals and the same curve in every band."""
    curve = curve or {"recall": [0.2, 0.6], "precision": [1.0, 0.5], "precision_envelope": [1.0, 0.5]}
    # Intervals as wide as they print ("[100.0, 100.0]") make the widest AP cells.
    ci = {band: None if ap.get(band) is None else [ap[band], 1.0] for band in BANDS}
    return {"ap": {band: ap.get(band) for band in BANDS}, "ci": ci,
            "pr_curves": {band: curve for band in BANDS}, "n_frames": 10}


def add_scored(store: Store, team_token: str, ap: dict[str, float | None], curve: dict | None = None,
               **meta_overrides) -> int:
    """Record a submission of the token's team as scored with ``ap`` on the public part; returns its id."""
    team = store.team_for_token(team_token)
    body = repr((team.name, ap, meta_overrides)).encode()
    sha256 = hashlib.sha256(body).hexdigest()
    submission_id = store.add_submission(team, body, sha256, meta(**meta_overrides), quota=1000)
    assert store.claim_next() == submission_id
    scores = {"public": part_score(ap, curve), "private": part_score(ap, curve), "protocol_name": "test",
              "protocol_version": "1", "evaluator_version": "1", "gt_sha256": "0" * 64}
    assert store.record_score(submission_id, sha256, scores)
    return submission_id


def board_with(tmp: Path, rows: list[tuple[str, str, dict]]) -> Store:
    """A store with one scored entry per ``(team, method, ap)``, in that submission order."""
    store = Store(tmp / "board.db")
    tokens: dict[str, str] = {}
    for team, method, ap in rows:
        if team not in tokens:
            tokens[team] = store.add_team(team)
        add_scored(store, tokens[team], ap, method=method)
    return store
