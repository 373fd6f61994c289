"""Score a valid submission on the public and private parts with the official evaluator.

Only what the leaderboard shows leaves this module: per-band AP in percent rounded to 0.1 points,
bootstrap intervals rounded the same way, and precision-recall curves thinned to at most
``MAX_CURVE_POINTS`` points rounded to 0.001. Counts of ground truths, true and false positives and
anything per frame are dropped here, so the store never holds them.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from zendar_dataset.eval import evaluate
from zendar_dataset.eval.evaluate import scene_of
from zendar_dataset.eval.protocol import PROTOCOL_NAME, PROTOCOL_VERSION, protocol_dict
from zendar_leaderboard.ground_truth import PARTS, TestSplit

MAX_CURVE_POINTS = 50
BANDS = ("near", "mid", "far", "all")


def ap_points(ap: float | None) -> float | None:
    """AP in [0, 1] as percent rounded to 0.1 points (None stays None).

    Examples
    --------
    >>> ap_points(0.65249), ap_points(None)
    (65.2, None)
    """
    return None if ap is None else round(100.0 * ap, 1)


def _thin_curve(curve: dict[str, list[float]]) -> dict[str, list[float]]:
    n = len(curve["recall"])
    keep = range(n) if n <= MAX_CURVE_POINTS else np.unique(np.linspace(0, n - 1, MAX_CURVE_POINTS).round().astype(int))
    return {
        key: [round(curve[key][i], 3) for i in keep]
        for key in ("recall", "precision", "precision_envelope")
    }


def score_part(document: dict, test_split: TestSplit, part: str, *, bootstrap: int, seed: int = 0) -> dict[str, Any] | None:
    """The shown score of ``document`` on one part of the test split, or None for an empty part.

    Parameters
    ----------
    document
        A submission that passed :func:`zendar_leaderboard.submission.check_submission`.
    test_split
        The hidden labels.
    part
        ``"public"`` or ``"private"``.
    bootstrap
        Scene resamples for 95% intervals (skipped when the part has a single scene).

    Returns
    -------
    dict or None
        ``{"ap": {band: percent | None}, "ci": {band: [low, high]} | None, "pr_curves": {band:
        {"recall", "precision", "precision_envelope"}}, "n_frames": int}``.
    """
    frame_ids = test_split.part_frame_ids(part)
    if not frame_ids:
        return None
    results = document["results"]
    predictions = {"meta": {}, "results": {f: results[f] for f in frame_ids}}
    n_scenes = len({scene_of(f) for f in frame_ids})
    metrics = evaluate(
        predictions, test_split.part_ground_truth(part), bootstrap=bootstrap if n_scenes >= 2 else 0, seed=seed
    )
    ci = None
    if "bootstrap" in metrics:
        ci = {
            band: None if metrics["bootstrap"][band]["low"] is None
            else [ap_points(metrics["bootstrap"][band]["low"]), ap_points(metrics["bootstrap"][band]["high"])]
            for band in BANDS
        }
    return {
        "ap": {band: ap_points(metrics["ap"][band]) for band in BANDS},
        "ci": ci,
        "pr_curves": {band: _thin_curve(metrics["pr_curves"][band]) for band in BANDS},
        "n_frames": len(frame_ids),
    }


def score_submission(document: dict, test_split: TestSplit, *, bootstrap: int, seed: int = 0) -> dict[str, Any]:
    """Both parts' shown scores and the protocol they were computed under.

    Returns
    -------
    dict
        ``{"public": part score | None, "private": part score | None, "protocol_name",
        "protocol_version", "evaluator_version", "gt_sha256"}``.
    """
    scores: dict[str, Any] = {
        part: score_part(document, test_split, part, bootstrap=bootstrap, seed=seed) for part in PARTS
    }
    scores["protocol_name"] = PROTOCOL_NAME
    scores["protocol_version"] = PROTOCOL_VERSION
    scores["evaluator_version"] = protocol_dict()["evaluator_version"]
    scores["gt_sha256"] = test_split.sha256
    return scores
