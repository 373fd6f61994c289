"""Confidence intervals for AP by resampling units of frames with replacement.

Frames close in time are correlated (the same cars seen over consecutive frames), so whole groups of
them are resampled: by default the scene; with a block length, each scene's consecutive frames cut into
time blocks (:func:`frame_blocks`), finer units that still keep a car's stay in a band together.
Matching does not depend on which other frames are in the set, so it is done once; a resample only
re-weights each unit's detections and ground truth by how often the unit was drawn, which equals
duplicating the unit's frames.

The pure functions at the bottom (:func:`frame_blocks`, :func:`distinct_resamples`,
:func:`resample_weights`, :func:`resampled_average_precision`) are shared with the paired
comparisons of :mod:`zendar_dataset.eval.paired`.
"""

from __future__ import annotations

from dataclasses import dataclass

import math

import numpy as np

from zendar_dataset.eval.ap import curve_from_cumulative, sort_by_score
from zendar_dataset.eval.protocol import BOOTSTRAP_CONFIDENCE


@dataclass(frozen=True)
class BandDetections:
    """One band's scored detections and ground truth, tagged with their resampling unit.

    Attributes
    ----------
    score
        float64 (N,).
    is_tp
        bool (N,).
    scene
        int64 (N,): resampling unit of each detection (a scene, or a scene's time block), in ``[0, S)``.
    gt_scene
        int64 (G,): resampling unit of each of the band's ground truths.
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
    """Percentile confidence intervals of AP per band over unit resamples.

    Parameters
    ----------
    bands
        Band name → its detections; unit indices refer to one list of S units (scenes or blocks).
    n_scenes
        S, the number of units.
    n_resamples
        Number of resamples (each draws S units with replacement, :func:`resample_weights`).
    seed
        Seed of ``numpy.random.default_rng``; the same seed and data give the same intervals.

    Returns
    -------
    dict
        ``{band: {"low": float | None, "high": float | None, "n": int}}``, ``n`` the number of
        resamples in which the band had ground truth (AP defined).
    """
    weights = resample_weights(n_scenes, n_resamples, seed)
    tail_percent = 50.0 * (1.0 - BOOTSTRAP_CONFIDENCE)
    intervals = {}
    for name, band in bands.items():
        aps = resampled_average_precision(band, weights)
        defined = aps[np.isfinite(aps)]
        if len(defined) == 0:
            intervals[name] = {"low": None, "high": None, "n": 0}
            continue
        low, high = np.percentile(defined, [tail_percent, 100.0 - tail_percent])
        intervals[name] = {"low": float(low), "high": float(high), "n": int(len(defined))}
    return intervals


def frame_blocks(frame_scene: np.ndarray, timestamp_ns: np.ndarray, block_s: float) -> tuple[np.ndarray, int]:
    """Cut each scene's frames into consecutive time blocks of ``block_s``: the resampling units.

    A scene's block k holds its frames with ``k * block_s <= t - t_first < (k + 1) * block_s``,
    ``t_first`` the scene's first frame. A last block shorter than half ``block_s`` (from its first
    frame to the scene's last) joins the block before it, so that no unit is a sliver of a few
    frames. Blocks never span two scenes.

    Parameters
    ----------
    frame_scene
        int64 (F,): scene index of each frame, any order.
    timestamp_ns
        int64 (F,): each frame's timestamp, nanoseconds.
    block_s
        Block length, seconds (> 0).

    Returns
    -------
    (frame_block, n_blocks)
        int64 (F,): block index of each frame, numbered in (scene, time) order from 0; and the
        number of blocks.
    """
    if not block_s > 0:
        raise ValueError(f"block_s must be positive, got {block_s}")
    frame_scene = np.asarray(frame_scene, dtype=np.int64)
    timestamp_ns = np.asarray(timestamp_ns, dtype=np.int64)
    if frame_scene.shape != timestamp_ns.shape or frame_scene.ndim != 1:
        raise ValueError("frame_scene and timestamp_ns must share one 1-D shape")
    frame_block = np.zeros(len(frame_scene), dtype=np.int64)
    if len(frame_scene) == 0:
        return frame_block, 0
    # Timestamps are whole nanoseconds, so any block of half a nanosecond or less puts every
    # timestamp in a block of its own, none of which can join the (empty) block before it: exactly
    # what half a nanosecond gives. The floor keeps elapsed / block finite for a block of 1e-300 s.
    block_ns = max(block_s * 1e9, 0.5)
    n_blocks = 0
    for scene in np.unique(frame_scene):
        in_scene = np.flatnonzero(frame_scene == scene)
        elapsed_ns = timestamp_ns[in_scene] - timestamp_ns[in_scene].min()
        # Block numbers stay float64: only their order and equality matter, and a cast to int64
        # would overflow for spans beyond 2**62 ns at the shortest block.
        k = np.floor(elapsed_ns / block_ns)
        last = k.max()
        if last > 0 and (elapsed_ns.max() - elapsed_ns[k == last].min()) < 0.5 * block_ns:
            k[k == last] = last - 1
        used, dense = np.unique(k, return_inverse=True)  # a gap in time leaves no empty block
        frame_block[in_scene] = n_blocks + dense
        n_blocks += len(used)
    return frame_block, n_blocks


def distinct_resamples(n_units: int) -> int:
    """Distinct bootstrap resamples of ``n_units`` units: multisets of size n from n, C(2n − 1, n).

    Two draws that pick the same units the same number of times, in any order, give the same
    resampled AP, so this bounds how many different values a bootstrap can show (3 for 2 units,
    126 for 5, 462 for 6); 0 for no unit.
    """
    if n_units < 0:
        raise ValueError(f"n_units must be 0 or more, got {n_units}")
    return math.comb(2 * n_units - 1, n_units) if n_units else 0


def resample_weights(n_units: int, n_resamples: int, seed: int = 0) -> np.ndarray:
    """How often each unit is drawn in each resample (each draws ``n_units`` with replacement).

    Parameters
    ----------
    n_units
        U.
    n_resamples
        R.
    seed
        Seed of ``numpy.random.default_rng``.

    Returns
    -------
    numpy.ndarray
        int64 (R, U); every row sums to U. The same arguments give the same array, so two
        detectors scored with the same ``(n_units, n_resamples, seed)`` see the same resamples.
    """
    rng = np.random.default_rng(seed)
    if n_units == 0:
        return np.zeros((n_resamples, 0), dtype=np.int64)
    draws = rng.integers(0, n_units, size=(n_resamples, n_units))
    flat = (draws + n_units * np.arange(n_resamples)[:, None]).ravel()
    return np.bincount(flat, minlength=n_resamples * n_units).reshape(n_resamples, n_units).astype(np.int64)


def resampled_average_precision(band: BandDetections, weights: np.ndarray) -> np.ndarray:
    """AP of ``band`` in each resample: float64 (R,), NaN where the resample has no ground truth.

    Parameters
    ----------
    band
        The band's detections, unit indices in ``[0, U)``.
    weights
        int64 (R, U), as from :func:`resample_weights`.
    """
    order, group_ends = sort_by_score(band.score)
    return np.array(
        [weighted_average_precision(band, unit_weight, order, group_ends) for unit_weight in weights],
        dtype=np.float64,
    )
