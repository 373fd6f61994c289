"""Row segments: the local reference points that keep float32 backprojection accurate.

Both backprojection backends split every image row into segments of ``S`` adjacent
pixels and reference each pixel to its segment's centre ``c``: pixel ``x = c + m·dj``
with ``m`` a small offset in pixels. For a pulse at ``p`` with ``d = p − c`` (float64,
exact even in ECEF) and ``R_ref = |d|`` (float64), the pixel's range obeys exactly

    R² = R_ref² + s,   s = m·(m·|dj|² − 2·dj·d),
    R − R_ref = s / (R + R_ref),

so the per-pixel float32 arithmetic only ever sees the small difference
``R − R_ref`` (at most half a segment), never a range of tens of metres nor an ECEF
coordinate of millions. The phase, ``2·R/λ`` turns, is split further so no float32
value carries many whole turns:

    2R/λ = 2R_ref/λ + m·g·2/λ + (R − R_ref − m·g)·2/λ,   g = −dj·d / R_ref,

the first two reduced modulo one turn in float64 (the second per half pixel, as
``2m`` is an odd integer), the third, the segment's curvature
``(m²·|dj|² + m·(b/2R_ref)·(R − R_ref)) / (R + R_ref)`` with ``b = 2·dj·d``, small.
The phase error stays ~1e-5 turn, against ~1e-2 rad for ranges formed in float32
from positions relative to a single image-wide reference.
"""

from __future__ import annotations

import numpy as np

# A segment spans at most this many metres (64 pixels of 4 cm): shorter segments
# make the float32 difference R − R_ref smaller (more accurate), longer ones
# amortise the float64 per-(segment, pulse) work and vectorise better (measured:
# 32 / 48 / 64 pixels of 4 cm give 0.43 / 0.45 / 0.47 G pixel·pulses/s).
_SEGMENT_EXTENT_M = 2.56
_MIN_SEGMENT_PX = 16
_MAX_SEGMENT_PX = 64


def segment_length_px(dj: np.ndarray) -> int:
    """Pixels per row segment for column step ``dj`` (metres), a multiple of 16."""
    step_m = float(np.linalg.norm(dj))
    length = 16 * int(_SEGMENT_EXTENT_M / step_m / 16 + 1e-9)
    return int(np.clip(length, _MIN_SEGMENT_PX, _MAX_SEGMENT_PX))
