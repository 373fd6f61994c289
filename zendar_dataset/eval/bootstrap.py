"""Confidence intervals for AP by resampling scenes with replacement.

Frames of one scene are correlated (the same cars seen over consecutive frames), so the scene is the
resampling unit. Matching does not depend on which other frames are in the set, so it is done once;
a resample only re-weights each scene's detections and ground truth by how often the scene was drawn,
which equals duplicating the scene's frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from zendar_dataset.eval.ap import curve_from_cumulative, sort_by_score
from zendar_dataset.eval.protocol import BOOTSTRAP_CONFIDENCE


@dataclass(frozen=True)
class BandDetections:
    """One band's scored detections and ground truth, tagged with their scene.

    Attributes
    ----------
    score
        float64 (N,).
    is_tp
        bool (N,).
    scene
        int64 (N,): scene index of each detection, in ``[0, S)``.
    gt_scene
        int64 (G,): scene index of each of the band's ground truths.
    """

    score: np.ndarray
    is_tp: np.ndarray
    scene: np.ndarray
    gt_scene: np.ndarray

    def __post_init__(self) -> None:
        n = self.score.shape
        if self.is_tp.shape != n or self.scene.shape != n or self.score.ndim != 1 or self.gt_scene.ndim != 1:
            raise ValueError("score, is_tp and scene must share one 1-D shape; gt_scene must be 1-D")


def weighted_average_precision(
    band: BandDetections, scene_weight: np.ndarray, order: np.ndarray, group_ends: np.ndarray
) -> float:
    """AP of ``band`` with every scene counted ``scene_weight[s]`` times (NaN when no ground truth).

    Parameters
    ----------
    band
        The band's detections.
    scene_weight
        int64 (S,): multiplicity of each scene.
    order, group_ends
        ``sort_by_score(band.score)``, computed once for all resamples.
    """
    n_gt = int(scene_weight[band.gt_scene].sum())
    if n_gt == 0:
        return float("nan")
    weight = scene_weight[band.scene[order]]
    weight_cumulative = np.cumsum(weight)[group_ends]
    tp_cumulative = np.cumsum(weight * band.is_tp[order])[group_ends]
    # A score whose scenes were all left out of this resample is no step at all.
    present = np.diff(weight_cumulative, prepend=0) > 0
    tp_cumulative = tp_cumulative[present].astype(np.float64)
    fp_cumulative = weight_cumulative[present].astype(np.float64) - tp_cumulative
    if len(tp_cumulative) == 0:
        return 0.0
    return curve_from_cumulative(tp_cumulative, fp_cumulative, float(n_gt))[3]


def bootstrap_intervals(
    bands: dict[str, BandDetections], n_scenes: int, n_resamples: int, seed: int = 0
) -> dict[str, dict]:
    """Percentile confidence intervals of AP per band over scene resamples.

    Parameters
    ----------
    bands
        Band name → its detections; scene indices refer to one sorted list of S scenes.
    n_scenes
        S.
    n_resamples
        Number of resamples (each draws S scenes with replacement).
    seed
        Seed of ``numpy.random.default_rng``; the same seed and data give the same intervals.

    Returns
    -------
    dict
        ``{band: {"low": float | None, "high": float | None, "n": int}}``, ``n`` the number of
        resamples in which the band had ground truth (AP defined).
    """
    rng = np.random.default_rng(seed)
    draws = rng.integers(0, n_scenes, size=(n_resamples, n_scenes)) if n_scenes else np.zeros((n_resamples, 0), int)
    tail_percent = 50.0 * (1.0 - BOOTSTRAP_CONFIDENCE)
    intervals = {}
    for name, band in bands.items():
        order, group_ends = sort_by_score(band.score)
        aps = np.array(
            [
                weighted_average_precision(band, np.bincount(draw, minlength=n_scenes), order, group_ends)
                for draw in draws
            ],
            dtype=np.float64,
        )
        defined = aps[np.isfinite(aps)]
        if len(defined) == 0:
            intervals[name] = {"low": None, "high": None, "n": 0}
            continue
        low, high = np.percentile(defined, [tail_percent, 100.0 - tail_percent])
        intervals[name] = {"low": float(low), "high": float(high), "n": int(len(defined))}
    return intervals
