"""Distinct labelled cars per range band and split of a run, by kind of motion: how much the data can tell.

The counting is :mod:`zendar_dataset.eval.car_counts` (a car is a track id of a scene, counted in a
band when labelled there in at least one frame; its kind of motion read from its headings); this
module picks a run's splits — the labelled part of the training split counted on its labelled
segments alone — and writes the table of ``table.md``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from zendar_baselines.labels.splits import SemiSupervisedSplit

from zendar_dataset.eval.car_counts import MOTION_KINDS, scenes_car_counts
from zendar_dataset.eval.protocol import BAND_NAMES
from zendar_dataset.format.reader import DatasetIndex


def split_car_counts(dataset: DatasetIndex, split: SemiSupervisedSplit) -> dict[str, Any]:
    """Distinct cars of the labelled part (``train_labelled``: the rows of its labelled segments), and of
    the ``train``, ``val`` and ``test`` splits, each :meth:`zendar_dataset.eval.car_counts.CarCounts.to_json`.
    """

    def labelled_times(scene_id: str):
        return lambda timestamps_ns: split.is_labelled(scene_id, np.asarray(timestamps_ns, np.int64))

    counts = {"train_labelled": scenes_car_counts(dataset, split.labelled, keep_times=labelled_times)}
    counts.update({name: scenes_car_counts(dataset, dataset.scene_ids(name)) for name in ("train", "val", "test")})
    return {name: value.to_json() for name, value in counts.items()}


def markdown_car_counts(counts_by_split: dict[str, dict[str, Any]]) -> str:
    """A Markdown table: one line per split, per band the distinct cars (ahead/oncoming/crossing/turning)."""
    lines = [
        "| split | " + " | ".join(BAND_NAMES) + " |",
        "|---|" + "--:|" * len(BAND_NAMES),
    ]
    for split, counts in counts_by_split.items():
        cells = [f"{counts['cars'][band]} ({'/'.join(str(counts['by_kind'].get(band, {}).get(k, 0)) for k in MOTION_KINDS)})"
                 for band in BAND_NAMES]
        lines.append(f"| {split} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + f"\n\nDistinct labelled cars per band (by kind: {'/'.join(MOTION_KINDS)}).\n"
