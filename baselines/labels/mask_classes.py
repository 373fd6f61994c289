"""The classes of a range-Doppler dynamic-object mask (paper §2.3, Fig. 2).

A mask is uint8 ``[R, D]`` per radar cube (range bins × Doppler bins). UNCERTAIN marks cells whose
class the automatic labelling cannot decide: a cluster holding both moving and stationary points
(Fig. 2, blue), or cells just outside a labelled box where range and DOA error blur the boundary.
"""

from __future__ import annotations

import numpy as np

BACKGROUND = 0
MOVING = 1
UNCERTAIN = 2
#: Every value a mask may hold, in order.
MASK_CLASSES = (BACKGROUND, MOVING, UNCERTAIN)
MASK_DTYPE = np.dtype(np.uint8)

__all__ = ["BACKGROUND", "MASK_CLASSES", "MASK_DTYPE", "MOVING", "UNCERTAIN"]
