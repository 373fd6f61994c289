"""Paired bootstrap of AP differences: is one detector better than another, per band?

Two detectors scored on the same frames are compared over the **same** resamples of those frames'
units (:func:`~zendar_dataset.eval.bootstrap.resample_weights` with one seed): whatever makes a
resample easy or hard (which cars, which ranges, which stretches of road) is shared by both, so the
interval of the difference is narrower than two separate intervals would suggest, and says what
the data can decide. The same holds for two bands of one detector (near against mid), resampled
together. A detector trained with several seeds enters as the mean of its seeds' APs, its seeds
drawn with replacement in every resample (:func:`pooled_over_seeds`).

A difference is taken in the claimed direction (the detector or band claimed better minus the
other); its verdict is ``"holds"`` when the whole interval is above 0, ``"fails"`` when it is below 0,
and ``"undecided"`` when it contains 0 (or no resample had ground truth in both).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from zendar_dataset.eval.bootstrap import (
    BandDetections,
    distinct_resamples,
    resampled_average_precision,
)
from zendar_dataset.eval.protocol import BOOTSTRAP_CONFIDENCE, MIN_DISTINCT_RESAMPLES

HOLDS = "holds"
FAILS = "fails"
UNDECIDED = "undecided"
#: Every verdict, in the order tables list them.
VERDICTS = (HOLDS, FAILS, UNDECIDED)


@dataclass(frozen=True)
class ResampledAP:
    """One band's AP on all frames and in each resample.

    Attributes
    ----------
    point : float
        AP with every unit counted once (the evaluator's AP); NaN when the band has no ground truth.
    resamples : numpy.ndarray
        float64 (R,): AP in each resample; NaN where the resample has no ground truth in the band.
    """

    point: float
    resamples: np.ndarray


@dataclass(frozen=True)
class PairedDifference:
    """A difference of two APs over shared resamples, its percentile interval and verdict.

    Attributes
    ----------
    difference : float or None
        AP(a) − AP(b) on all frames; None when either is undefined.
    low, high : float or None
        The 95 % percentile interval of the resampled differences; None when no resample had both.
    n : int
        Resamples in which both APs were defined.
    verdict : str
        ``"holds"``, ``"fails"`` or ``"undecided"`` (see the module docstring).
    """

    difference: float | None
    low: float | None
    high: float | None
    n: int
    verdict: str


def resampled_ap(band: BandDetections, weights: np.ndarray) -> ResampledAP:
    """AP of ``band`` on all frames and under each row of ``weights`` (int64 (R, U))."""
    n_units = weights.shape[1]
    point = resampled_average_precision(band, np.ones((1, n_units), dtype=np.int64))[0]
    return ResampledAP(float(point), resampled_average_precision(band, weights))


def seed_draws(n_resamples: int, n_seeds: int, rng: np.random.Generator) -> np.ndarray:
    """int64 ``[n_resamples, n_seeds]``: for each resample, ``n_seeds`` seed indices drawn with
    replacement (:func:`pooled_over_seeds`)."""
    return rng.integers(0, n_seeds, size=(n_resamples, n_seeds), dtype=np.int64)


def pooled_over_seeds(per_seed: Sequence[ResampledAP], draws: np.ndarray) -> ResampledAP:
    """One detector trained with several seeds, as the mean of its seeds' APs.

    On all frames, the mean of the seeds' APs. In resample ``r``, the mean over the seeds drawn for
    it (``draws[r]``, with replacement) of their APs in that resample: the interval then holds the
    spread between trainings as well as that of the frames, and a comparison does not hang on one
    training's luck. With one seed, that seed's APs unchanged.

    Parameters
    ----------
    per_seed
        Each seed's :class:`ResampledAP`, over the same resamples.
    draws
        int64 ``[R, S]`` seed indices (:func:`seed_draws`), ``S = len(per_seed)``; use the same
        draws for two bands of one detector, independent draws for different detectors.
    """
    if len(per_seed) == 1:
        return per_seed[0]
    resamples = np.stack([ap.resamples for ap in per_seed], axis=1)  # [R, S]
    if draws.shape != resamples.shape:
        raise ValueError(f"seed draws of shape {draws.shape} for {resamples.shape[1]} seeds and {resamples.shape[0]} resamples")
    drawn = np.take_along_axis(resamples, draws, axis=1)
    return ResampledAP(float(np.mean([ap.point for ap in per_seed])), drawn.mean(axis=1))


def verdict(low: float | None, high: float | None) -> str:
    """``"holds"`` when ``low > 0``, ``"fails"`` when ``high < 0``, else ``"undecided"``."""
    if low is None or high is None:
        return UNDECIDED
    if low > 0.0:
        return HOLDS
    if high < 0.0:
        return FAILS
    return UNDECIDED


def paired_difference(a: ResampledAP, b: ResampledAP) -> PairedDifference:
    """AP(a) − AP(b) with its percentile interval over the resamples both share.

    Parameters
    ----------
    a, b
        Resampled over the same weights (the same units, resamples and seed); ``a`` is the one
        claimed better.

    Returns
    -------
    PairedDifference
    """
    if a.resamples.shape != b.resamples.shape:
        raise ValueError(f"paired APs need the same resamples, got {a.resamples.shape} and {b.resamples.shape}")
    both = np.isfinite(a.resamples) & np.isfinite(b.resamples)
    difference = None if not (np.isfinite(a.point) and np.isfinite(b.point)) else a.point - b.point
    if not np.any(both):
        return PairedDifference(difference, None, None, 0, UNDECIDED)
    tail_percent = 50.0 * (1.0 - BOOTSTRAP_CONFIDENCE)
    low, high = np.percentile(a.resamples[both] - b.resamples[both], [tail_percent, 100.0 - tail_percent])
    return PairedDifference(difference, float(low), float(high), int(both.sum()), verdict(float(low), float(high)))


def too_few_resamples(n_units: int, where: str) -> str | None:
    """Why ``n_units`` units cannot give an interval, or None when they give enough distinct resamples.

    Parameters
    ----------
    n_units
        Resampling units (scenes or time blocks).
    where
        What was cut into units, for the message (``"test split, 2 s time blocks"``).

    Returns
    -------
    str or None
        A message when the units give fewer than
        :data:`~zendar_dataset.eval.protocol.MIN_DISTINCT_RESAMPLES` distinct resamples (fewer than 5
        units), else None.
    """
    distinct = distinct_resamples(n_units)
    if distinct >= MIN_DISTINCT_RESAMPLES:
        return None
    return (
        f"{where}: {n_units} resampling units give {distinct} distinct bootstrap resamples, fewer than "
        f"{MIN_DISTINCT_RESAMPLES}: an interval would be the spread of a handful of values, so none is given "
        "and every verdict is undecided. Give the split more or longer scenes, or resample shorter time "
        "blocks (5 units give 126)"
    )
