"""The official evaluator: center-distance matching and range-banded AP (docs/evaluation.md).

``evaluate(predictions, ground_truth)`` returns the ``metrics.json`` structure that
``zendar-eval`` writes.
"""

from __future__ import annotations

from zendar_dataset.eval.evaluate import evaluate, load_ground_truth
from zendar_dataset.eval.protocol import BANDS_M, MATCH_DISTANCE_M, protocol_dict

__all__ = ["evaluate", "load_ground_truth", "protocol_dict", "BANDS_M", "MATCH_DISTANCE_M"]
