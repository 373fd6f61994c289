"""The evaluation protocol as versioned data.

Everything that decides a score lives here, so that ``metrics.json`` can carry
the exact protocol it was computed under (see docs/evaluation.md).
"""

from __future__ import annotations

import copy
import functools
import importlib.metadata
from collections.abc import Mapping
from typing import Any

import numpy as np

PROTOCOL_NAME = "zendar-moving-car-center-distance"
PROTOCOL_VERSION = "1.0"

#: A prediction matches a ground truth whose center is strictly closer than this (paper §4.1:
#: half the length of an average car).
MATCH_DISTANCE_M = 2.5

#: The name of the band that spans all the others.
ALL_BAND = "all"

#: Range bands, half-open ``[low, high)`` in metres of r = sqrt(x² + y²) in the ego frame
#: (paper §4.3). ``all`` spans the three others; anything at r ≥ 60 m is in no band. This is the
#: one place band names are written: everything else takes them from here.
BANDS_M: dict[str, tuple[float, float]] = {
    "near": (0.0, 15.0),
    "mid": (15.0, 30.0),
    "far": (30.0, 60.0),
    ALL_BAND: (0.0, 60.0),
}

#: Every band, in the order metrics list them (``ALL_BAND`` last).
BAND_NAMES: tuple[str, ...] = tuple(BANDS_M)

#: The bands ``ALL_BAND`` spans, nearest first (the paper's Table 1 columns).
RANGE_BANDS: tuple[str, ...] = tuple(band for band in BANDS_M if band != ALL_BAND)

MAX_DETECTIONS_PER_FRAME = 500

#: Files larger than this are refused before parsing (1 GB); ``--max-bytes`` overrides it.
DEFAULT_MAX_BYTES = 1_000_000_000

#: metrics.json keeps at most this many points per precision-recall curve; longer curves are
#: thinned evenly (first and last points kept). AP is always computed on the full curve.
MAX_PR_CURVE_POINTS = 10_000

#: Most resamples ``--bootstrap N`` accepts: the percentile interval is settled long before, and the
#: resample draws (N × scenes int64) stay within memory.
MAX_BOOTSTRAP_RESAMPLES = 100_000

#: Bootstrap confidence level for ``--bootstrap N`` (percentile interval over unit resamples).
BOOTSTRAP_CONFIDENCE = 0.95

#: Fewest distinct resamples (multisets of units, ``bootstrap.distinct_resamples``) an interval needs to
#: be more than the spread of a handful of values: 5 units give 126, 4 give 35, 2 give 3.
MIN_DISTINCT_RESAMPLES = 100

#: Names of the resampling unit in ``protocol.bootstrap.unit``: whole scenes (the default), or each
#: scene's consecutive frames cut into time blocks of ``block_s`` seconds (``--bootstrap-block-s``).
BOOTSTRAP_UNIT_SCENE = "scene"
BOOTSTRAP_UNIT_BLOCK = "scene_time_block"

_PROTOCOL: dict[str, Any] = {
    "name": PROTOCOL_NAME,
    "version": PROTOCOL_VERSION,
    "coordinates": "ego frame of the frame's timestamp (format v1), metres; range r = sqrt(x^2 + y^2)",
    "match_distance_m": MATCH_DISTANCE_M,
    "match_rule": (
        "per frame, once over all ranges: predictions in descending score (equal scores keep list "
        "order) each take the nearest still-unmatched ground truth with center distance strictly "
        "less than match_distance_m (equal distances: the earlier ground-truth entry)"
    ),
    "bands_m": {name: list(bounds) for name, bounds in BANDS_M.items()},
    "band_rule": (
        "half-open [low, high); a matched prediction counts in the band of its ground truth's range, "
        "an unmatched one in the band of its own range; r >= 60 m is in no band"
    ),
    "ap_rule": (
        "precision/recall at each distinct score (ties form one step); precision replaced by its "
        "envelope (max over all higher recalls); AP = sum (R_n - R_{n-1}) * P_env(R_n); "
        "null when the band has no ground truth"
    ),
    "max_detections_per_frame": MAX_DETECTIONS_PER_FRAME,
    "default_max_bytes": DEFAULT_MAX_BYTES,
    "max_pr_curve_points": MAX_PR_CURVE_POINTS,
    "bootstrap": {"unit": BOOTSTRAP_UNIT_SCENE, "interval": "percentile", "confidence": BOOTSTRAP_CONFIDENCE},
}


@functools.cache
def _evaluator_version() -> str:
    try:
        return importlib.metadata.version("zendar-dataset")
    except importlib.metadata.PackageNotFoundError:  # running from a source tree, not installed
        from zendar_dataset import __version__

        return __version__


def protocol_dict(bootstrap_block_s: float | None = None) -> dict[str, Any]:
    """The protocol as a JSON-ready dict, with the evaluator's version.

    Parameters
    ----------
    bootstrap_block_s
        When given, the bootstrap resamples time blocks of this many seconds within scenes:
        ``bootstrap.unit`` is :data:`BOOTSTRAP_UNIT_BLOCK` and ``bootstrap.block_s`` is added.

    Returns
    -------
    dict
        A fresh copy; callers may modify it.
    """
    protocol = copy.deepcopy(_PROTOCOL)
    if bootstrap_block_s is not None:
        protocol["bootstrap"]["unit"] = BOOTSTRAP_UNIT_BLOCK
        protocol["bootstrap"]["block_s"] = float(bootstrap_block_s)
    protocol["evaluator_version"] = _evaluator_version()
    return protocol


def bootstrap_unit_text(protocol: Mapping[str, Any]) -> str:
    """The resampling unit a ``metrics.json`` protocol names, in words: ``"scene"`` or
    ``"2 s time block"`` (the unit's name as it is when the protocol predates or lacks it)."""
    bootstrap = protocol.get("bootstrap", {})
    unit = bootstrap.get("unit", BOOTSTRAP_UNIT_SCENE)
    if unit == BOOTSTRAP_UNIT_BLOCK and "block_s" in bootstrap:
        return f"{bootstrap['block_s']:g} s time block"
    return str(unit)


def range_m(x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
    """Ground-plane range r = sqrt(x² + y²).

    Parameters
    ----------
    x_m, y_m
        float64 arrays of shape (N,), ego frame, metres.

    Returns
    -------
    numpy.ndarray
        float64 (N,), metres.
    """
    return np.sqrt(x_m * x_m + y_m * y_m)


def in_band(r_m: np.ndarray, band: str) -> np.ndarray:
    """Boolean mask (N,) of ranges inside the half-open band ``[low, high)``."""
    low_m, high_m = BANDS_M[band]
    return (r_m >= low_m) & (r_m < high_m)
