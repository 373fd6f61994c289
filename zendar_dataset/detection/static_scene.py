"""The paper's static-scene test (§2.3): a radar point that lands on a dark SAR pixel is dynamic.

This module holds the one definition of "the SAR value of a point" (:func:`sar_db_at`), read by the
detection chain, the automatic labels, every Table 1 row and the fidelity report alike.

A SAR image is formed without compensating moving objects, so it images the static scene cleanly
and smears movers into the background (paper §1.1.2). A point on a static scatterer therefore
projects onto a bright pixel; a point on a moving car onto the noise and clutter floor.

The value read for a point is :meth:`zendar_dataset.sar.frames.SarFrames.brightest_db`: the
brightest pixel within :data:`zendar_dataset.sar.frames.SAR_SEARCH_RADIUS_M` of the point's
projection, in dB over the image's *median* magnitude. The median is the reference because the
image is mostly floor (thermal noise, clutter, smeared movers) with sparse bright static
scatterers, so the median is the floor's level whatever the gain of an image; the window's maximum
absorbs the DOA error of a point. On pure complex Gaussian noise the window maximum alone reads
about 6 dB (3 x 3 pixels, tiny profile) to 8 dB (7 x 7, demo profile) over the median: the median
of the largest of ``n`` exponential powers is ``ln(n / ln 2)`` times the mean power, against
``ln 2`` times the mean for the median pixel. The threshold sits above that noise reading and below
the static scatterers; its number is measured on the training split with
``python -m zendar_baselines.classical.chain_fit ROOT --split train`` (``zendar_baselines.classical.chain_fit``).

Points that no SAR image covers (beyond the images' 60 m, outside the radars' field of view, or with
no SAR frame near their time) read NaN: the test cannot confirm them static, nor call them dynamic.
:func:`is_dynamic` returns False for them, so no detection or moving label rests on a point without
SAR evidence; the automatic labels count such points as not dynamic when they judge a cluster, so
a cluster mixing them with dynamic points is uncertain.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from zendar_dataset.errors import ZendarError
from zendar_dataset.sar.frames import SAR_SEARCH_RADIUS_M, SarFrames

# Fitted on the training split (3 scenes, 180 frames, 8944 CFAR points) of
# `zendar-data synth ROOT --profile demo --scenes 5` by `python -m zendar_baselines.classical.chain_fit ROOT`:
# the value that best separates the CFAR points inside labelled boxes from the others (Youden's J;
# ROC AUC 0.74). Points on moving cars read a median 20 dB, the others 31 dB: the demo's 0.25 m
# apertures smear a moving car far less than the paper's 2 m ones, so cars stay well above the noise.
DEFAULT_THRESHOLD_DB = 25.5
# SAR frames come at 10 Hz; a point is read in the frame nearest its time, but not one farther
# than this (the scene, and with it the image's coverage, moves on).
DEFAULT_MAX_FRAME_GAP_NS = 150_000_000


@dataclass(frozen=True)
class SarTestParams:
    """Settings of the static-scene test.

    Attributes
    ----------
    threshold_db : float
        A point is dynamic when its SAR value (dB over the image's median magnitude, brightest pixel
        within :data:`~zendar_dataset.sar.frames.SAR_SEARCH_RADIUS_M`) is below this.
    max_frame_gap_ns : int
        A point is read only in SAR frames at most this far from its timestamp.
    """

    threshold_db: float = DEFAULT_THRESHOLD_DB
    max_frame_gap_ns: int = DEFAULT_MAX_FRAME_GAP_NS

    def __post_init__(self) -> None:
        if not np.isfinite(self.threshold_db):
            raise ZendarError(f"SarTestParams.threshold_db must be a finite number of dB, got {self.threshold_db!r}")
        if self.max_frame_gap_ns < 0:
            raise ZendarError(f"SarTestParams.max_frame_gap_ns must be >= 0, got {self.max_frame_gap_ns!r}")

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict, with the search radius the values were read with."""
        return {**asdict(self), "search_radius_m": SAR_SEARCH_RADIUS_M, "reference": "median SAR magnitude"}


def nearest_frames(sar: SarFrames, timestamp_ns: int, max_gap_ns: int) -> dict[str, int]:
    """Per SAR sensor, the index of the frame nearest ``timestamp_ns`` within ``max_gap_ns``.

    Returns
    -------
    dict of str to int
        Sensor name -> frame index; sensors without a frame close enough are left out.
    """
    found = {}
    for sensor in sar.sensors:
        stamps = sar.timestamps[sensor]
        if stamps.size == 0:
            continue
        k = int(np.argmin(np.abs(stamps - np.int64(timestamp_ns))))
        if abs(int(stamps[k]) - int(timestamp_ns)) <= max_gap_ns:
            found[sensor] = k
    return found


def sar_db_at(
    sar: SarFrames, points_ecef: np.ndarray, timestamp_ns: int, *, max_frame_gap_ns: int = DEFAULT_MAX_FRAME_GAP_NS
) -> np.ndarray:
    """The static-scene test's value of points seen at ``timestamp_ns``.

    Parameters
    ----------
    sar : SarFrames
        The scene's SAR images.
    points_ecef : numpy.ndarray
        ``[N, 3]`` float64 ECEF metres.
    timestamp_ns : int
        When the points were seen; each SAR sensor's frame nearest this time (within
        ``max_frame_gap_ns``) is read.
    max_frame_gap_ns : int
        See :class:`SarTestParams`.

    Returns
    -------
    numpy.ndarray
        ``[N]`` float64 dB over the image's median magnitude, the brightest reading over the SAR
        sensors' images that cover the point (a static scatterer is static in every image that sees
        it); NaN where no image covers the point.
    """
    points_ecef = np.asarray(points_ecef, np.float64)
    if points_ecef.ndim != 2 or points_ecef.shape[1] != 3:
        raise ZendarError(f"sar_db_at: points_ecef must be [N, 3], got shape {points_ecef.shape}")
    out = np.full(points_ecef.shape[0], np.nan)
    if points_ecef.shape[0] == 0:
        return out
    for sensor, frame in nearest_frames(sar, timestamp_ns, max_frame_gap_ns).items():
        out = np.fmax(out, sar.brightest_db(sensor, frame, points_ecef))
    return out


def is_dynamic(sar_db: np.ndarray, params: SarTestParams | None = None) -> np.ndarray:
    """``[N]`` bool: the SAR value is below the threshold; False where it is NaN (module docstring).

    Parameters
    ----------
    sar_db : numpy.ndarray
        ``[N]`` float64 values from :func:`sar_db_at`.
    params : SarTestParams, optional
        The threshold (default :class:`SarTestParams`).
    """
    params = SarTestParams() if params is None else params
    return np.asarray(sar_db, np.float64) < params.threshold_db  # NaN compares False
