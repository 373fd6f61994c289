"""Checking the SAR buffer's pixel order against points whose ECEF position is known.

The release's pixel buffer is ``rows × cols`` values; which of the two
flat orders holds pixel (i, j) is not stated (the SDK viewer reads flat
element ``j·rows + i``).  Radar detections and lidar points carry ECEF
positions: projected through the image model they should fall on bright
pixels under the right reading, and on background under the wrong one.
"""

from __future__ import annotations

import numpy as np

from zendar_dataset.geometry.frames import ecef_to_sar_pixel
from zendar_dataset.release.records import SarFrame, sar_flat

_MAX_FRAMES = 20
_MAX_DT_S = 0.05
_DECISIVE_RATIO = 2.0
_MIN_POINTS = 5
_REPORT_CAP_DB = 60.0  # beyond this the figure says nothing more (a bright pixel against a zero background)


def _background(flat: np.ndarray) -> float:
    """The buffer's median magnitude, from a sparse sample of it (a full median per 512×512 frame would
    cost more than decoding it)."""
    sample = np.abs(flat[:: max(1, flat.size // 4096)])
    return float(np.median(sample)) or float(np.mean(sample)) or 1.0


def _brightness(flat: np.ndarray, index: np.ndarray, background: float) -> float:
    """Median magnitude at flat ``index`` over the buffer's ``background``."""
    return float(np.median(np.abs(flat[index]))) / background


def vote_pixel_order(frames: list[SarFrame], probes: list[tuple[float, np.ndarray]]) -> tuple[bool | None, str]:
    """Which flat order makes known ECEF points land on bright pixels.

    Parameters
    ----------
    frames
        SAR frames of one radar (the first ones are used).
    probes
        ``(GPS seconds, [P, 3] ECEF metres)`` point sets (detections, lidar sweeps).

    Returns
    -------
    i_fastest : bool or None
        True: flat element ``j·rows + i``; False: ``i·cols + j``; None: the evidence does not decide
        (too few points in the images, square images with symmetric content, ...).
    evidence : str
        The brightness ratio measured (geometric mean over the frames used, in dB, capped at
        ±60 dB), for the import summary.
    """
    if not probes:
        return None, "no detections or lidar points to check against"
    times = np.array([t for t, _ in probes])
    log_ratios = []
    used = 0
    for frame in frames[:_MAX_FRAMES]:
        k = int(np.argmin(np.abs(times - frame.timestamp_s)))
        if abs(times[k] - frame.timestamp_s) > _MAX_DT_S:
            continue
        points = probes[k][1]
        points = points[np.all(np.isfinite(points), axis=1)]
        if not points.size:
            continue
        try:
            i, j, _ = ecef_to_sar_pixel(points, frame.origin_ecef, frame.di_ecef, frame.dj_ecef)
        except ValueError:
            continue
        i, j = np.rint(i).astype(np.int64), np.rint(j).astype(np.int64)
        inside = (i >= 0) & (i < frame.rows) & (j >= 0) & (j < frame.cols)
        if not np.any(inside):
            continue
        try:
            flat, _ = sar_flat(frame)
        except ValueError:
            continue
        i, j = i[inside], j[inside]
        background = _background(flat)  # the same under both readings
        score_a = _brightness(flat, j * frame.rows + i, background)
        score_b = _brightness(flat, i * frame.cols + j, background)
        log_ratios.append(np.log(max(score_a, 1e-12) / max(score_b, 1e-12)))
        used += int(np.count_nonzero(inside))
    if used < _MIN_POINTS:
        return None, f"only {used} known points fell inside the images"
    # Per frame, not their product: 20 frames of 10x are not 1e20x.
    ratio = float(np.exp(np.mean(log_ratios)))
    db = 20 * np.log10(ratio)  # a ratio of magnitudes
    figure = f"{db:+.1f} dB" if abs(db) <= _REPORT_CAP_DB else f"{'>' if db > 0 else '<'} {db / abs(db) * _REPORT_CAP_DB:+.0f} dB"
    text = f"{used} known points in {len(log_ratios)} frames: {figure} brighter under the SDK reading than row-major (geometric mean per frame)"
    if ratio >= _DECISIVE_RATIO:
        return True, text
    if ratio <= 1 / _DECISIVE_RATIO:
        return False, text
    return None, text
