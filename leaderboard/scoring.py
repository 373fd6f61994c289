"""Score a valid submission on the public and private parts with the official evaluator.

Only what the leaderboard shows leaves this module: per-band AP as a fraction in [0, 1] rounded to
0.001 (= 0.1 AP points, the shown precision), bootstrap intervals rounded the same way, and
precision-recall curves thinned to at most ``MAX_CURVE_POINTS`` points rounded to 0.001. Counts of
ground truths, true and false positives and anything per frame are dropped here, so the store never
holds them. Pages and the ``submit`` table show AP in percent via :func:`format_ap_percent`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from zendar_dataset.eval import evaluate_record
from zendar_dataset.eval.evaluate import scene_of
from zendar_dataset.eval.protocol import BAND_NAMES, PROTOCOL_NAME, PROTOCOL_VERSION, protocol_dict
from zendar_dataset.eval.records import PRCurve
from zendar_leaderboard.ground_truth import PARTS, TestSplit

MAX_CURVE_POINTS = 50
#: The bands every leaderboard score, page and table lists: the evaluator's.
BANDS = BAND_NAMES


def shown_ap(ap: float | None) -> float | None:
    """AP in [0, 1] as stored and served: a fraction rounded to 0.001 = 0.1 AP points (None stays None).

    Every JSON the leaderboard emits carries AP in this form, like the evaluator's ``metrics.json``.

    Examples
    --------
    >>> shown_ap(0.65249), shown_ap(1.0), shown_ap(None)
    (0.652, 1.0, None)
    """
    return None if ap is None else round(float(ap), 3)


def format_ap_percent(ap: float | None, missing: str = "–") -> str:
    """A stored AP fraction as percent with one decimal, for pages and printed tables.

    The fraction is already rounded to 0.001, so this only moves the decimal point: what a page
    shows and what the JSON carries never disagree.

    Examples
    --------
    >>> format_ap_percent(0.833), format_ap_percent(1.0), format_ap_percent(None)
    ('83.3', '100.0', '–')
    """
    return missing if ap is None else f"{100.0 * ap:.1f}"


def _thin_curve(curve: PRCurve) -> dict[str, list[float]]:
    n = len(curve.recall)
    keep = range(n) if n <= MAX_CURVE_POINTS else np.unique(np.linspace(0, n - 1, MAX_CURVE_POINTS).round().astype(int))
    return {
        "recall": [round(curve.recall[i], 3) for i in keep],
        "precision": [round(curve.precision[i], 3) for i in keep],
        "precision_envelope": [round(curve.precision_envelope[i], 3) for i in keep],
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
        ``{"ap": {band: fraction | None}, "ci": {band: [low, high] | None} | None, "pr_curves": {band:
        {"recall", "precision", "precision_envelope"}}, "n_frames": int}``; AP and interval ends
        in [0, 1] rounded to 0.001 (:func:`shown_ap`), None for a band without ground truth.
    """
    frame_ids = test_split.part_frame_ids(part)
    if not frame_ids:
        return None
    results = document["results"]
    predictions = {"meta": {}, "results": {f: results[f] for f in frame_ids}}
    n_scenes = len({scene_of(f) for f in frame_ids})
    metrics = evaluate_record(
        predictions, test_split.part_ground_truth(part), bootstrap=bootstrap if n_scenes >= 2 else 0, seed=seed
    )
    ci = None
    if metrics.bootstrap is not None:
        ci = {
            band: None if metrics.bootstrap[band].low is None
            else [shown_ap(metrics.bootstrap[band].low), shown_ap(metrics.bootstrap[band].high)]
            for band in BANDS
        }
    return {
        "ap": {band: shown_ap(metrics.ap[band]) for band in BANDS},
        "ci": ci,
        "pr_curves": {band: _thin_curve(metrics.pr_curves[band]) for band in BANDS},
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
