"""The official evaluator: center-distance matching and range-banded AP (docs/evaluation.md).

``evaluate(predictions, ground_truth)`` returns the ``metrics.json`` structure that
``zendar-eval`` writes; ``evaluate_record(...)`` returns it as a typed
:class:`~zendar_dataset.eval.records.MetricsRecord`, and ``MetricsRecord.from_json`` reads it back.
"""

from __future__ import annotations

from zendar_dataset.eval.evaluate import evaluate, evaluate_record, load_ground_truth
from zendar_dataset.eval.protocol import (
    ALL_BAND,
    BAND_NAMES,
    BANDS_M,
    MATCH_DISTANCE_M,
    RANGE_BANDS,
    protocol_dict,
)
from zendar_dataset.eval.records import BandCounts, BootstrapInterval, MetricsRecord, PRCurve

__all__ = [
    "evaluate",
    "evaluate_record",
    "load_ground_truth",
    "protocol_dict",
    "BANDS_M",
    "BAND_NAMES",
    "RANGE_BANDS",
    "ALL_BAND",
    "MATCH_DISTANCE_M",
    "MetricsRecord",
    "BandCounts",
    "BootstrapInterval",
    "PRCurve",
]
