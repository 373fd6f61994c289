"""Table 1 of the paper from the benchmark's scored rows: ``results.json``, ``table.md``, ``table.csv``.

Pure functions on the evaluator's metrics: a row's AP per band is the mean over its seeds, with the
standard deviation across seeds and the evaluator's bootstrap interval (over time blocks of the test
scenes) of each seed. The paper's claims are decided in :mod:`zendar_baselines.bench.claims`.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from zendar_dataset.eval.protocol import BAND_NAMES, RANGE_BANDS
from zendar_dataset.eval.records import MetricsRecord

#: Our columns: every band of the evaluator. The paper's columns: the bands ``all`` spans.
BANDS = BAND_NAMES
TABLE_BANDS = RANGE_BANDS

#: Paper Table 1 (AP in percent on the recorded test set): (method, unsupervised, supervised) -> near, mid, far.
PAPER_AP_PERCENT: dict[tuple[str, bool, bool], tuple[float, float, float]] = {
    ("CFAR", False, False): (65.0, 43.0, 13.3),
    ("FPN ResNet-34", False, True): (66.3, 56.0, 22.8),
    ("FPN ResNet-34", True, True): (73.1, 63.4, 23.9),
    ("zoom-out DenseNet-37", False, True): (67.0, 59.8, 28.3),
    ("zoom-out DenseNet-37", True, True): (77.2, 68.1, 29.2),
    ("zoom-out DenseNet-67", False, True): (74.8, 58.8, 29.6),
    ("zoom-out DenseNet-67", True, True): (76.6, 67.6, 29.9),
}

#: Method names of Table 1 per architecture of ``zendar_baselines.cnn.models``.
METHOD_NAMES = {
    "cfar": "CFAR",
    "fpn-resnet34": "FPN ResNet-34",
    "densenet-37": "zoom-out DenseNet-37",
    "densenet-67": "zoom-out DenseNet-67",
}


@dataclass
class Row:
    """One line of Table 1 and the metrics of each of its seeds.

    Attributes
    ----------
    key : str
        Short, file-system safe name (``"cfar"``, ``"densenet-37-pretrained"``); the row's folder in ``--out``.
    method : str
        As the paper writes it (:data:`METHOD_NAMES`).
    unsupervised, supervised : bool
        Trained on automatic labels / on manual labels.
    seed_metrics : list of MetricsRecord
        The evaluator's metrics (``zendar_dataset.eval.evaluate_record``) of each seed, in seed order.
    """

    key: str
    method: str
    unsupervised: bool
    supervised: bool
    seed_metrics: list[MetricsRecord] = field(default_factory=list)

    def ap_mean(self) -> dict[str, float | None]:
        """Mean AP per band over the seeds (None where a band has no ground truth)."""
        return {band: _mean([m.ap[band] for m in self.seed_metrics]) for band in BANDS}

    def ap_std(self) -> dict[str, float | None]:
        """Sample standard deviation per band over the seeds (None for fewer than 2 seeds)."""
        return {band: _std([m.ap[band] for m in self.seed_metrics]) for band in BANDS}

    def paper_ap(self) -> dict[str, float] | None:
        """The paper's AP for this row as fractions, or None for a row the paper does not have."""
        figures = PAPER_AP_PERCENT.get((self.method, self.unsupervised, self.supervised))
        return None if figures is None else {band: round(value / 100.0, 4) for band, value in zip(TABLE_BANDS, figures)}

    def to_json(self) -> dict[str, Any]:
        """The row's entry of ``results.json``."""
        entry: dict[str, Any] = {
            "key": self.key,
            "method": self.method,
            "unsupervised": self.unsupervised,
            "supervised": self.supervised,
            "ap": _rounded(self.ap_mean()),
            "n_seeds": len(self.seed_metrics),
        }
        if len(self.seed_metrics) > 1:
            entry["ap_std"] = _rounded(self.ap_std())
            entry["ap_per_seed"] = [_rounded(m.ap) for m in self.seed_metrics]
        intervals = [m.bootstrap for m in self.seed_metrics]
        if intervals and all(intervals):
            entry["ap_ci95_per_seed"] = [
                {band: [_round(ci[band].low), _round(ci[band].high)] for band in BANDS} for ci in intervals
            ]
        first = self.seed_metrics[0] if self.seed_metrics else None
        entry["counts"] = None if first is None else {band: first.counts[band].to_json() for band in BANDS}
        entry["paper_ap"] = self.paper_ap()
        entry["metrics"] = f"rows/{self.key}/metrics.json"
        entry["predictions"] = f"rows/{self.key}/predictions.json"
        return entry


def _mean(values: list[float | None]) -> float | None:
    known = [v for v in values if v is not None]
    return None if not known or len(known) != len(values) else math.fsum(known) / len(known)


def _std(values: list[float | None]) -> float | None:
    mean = _mean(values)
    if mean is None or len(values) < 2:
        return None
    return math.sqrt(math.fsum((v - mean) ** 2 for v in values) / (len(values) - 1))


def _round(value: float | None) -> float | None:
    return None if value is None else round(float(value), 4)


def _rounded(by_band: Mapping[str, float | None]) -> dict[str, float | None]:
    return {band: _round(by_band[band]) for band in BANDS}


def _cell(mean: float | None, std: float | None) -> str:
    if mean is None:
        return "n/a"
    return f"{100 * mean:.1f}" if std is None else f"{100 * mean:.1f} ± {100 * std:.1f}"


def _mark(flag: bool) -> str:
    return "✓" if flag else "-"


def markdown_table(rows: list[Row], title: str) -> str:
    """Table 1 as Markdown: ours (mean ± std over seeds, percent) beside the paper's figures."""
    figures = [f"AP {band}" for band in BANDS] + [f"paper {band}" for band in TABLE_BANDS]
    lines = [
        f"### {title}",
        "",
        "| method | unsupervised | supervised | " + " | ".join(figures) + " |",
        "|---|:-:|:-:|" + "--:|" * len(figures),
    ]
    for row in rows:
        mean, std = row.ap_mean(), row.ap_std()
        paper = row.paper_ap()
        ours = [_cell(mean[band], std[band]) for band in BANDS]
        theirs = [f"{100 * paper[band]:.1f}" if paper else "" for band in TABLE_BANDS]
        lines.append(
            f"| {row.method} | {_mark(row.unsupervised)} | {_mark(row.supervised)} | " + " | ".join(ours + theirs) + " |"
        )
    return "\n".join(lines) + "\n"


def csv_table(rows: list[Row]) -> str:
    """One line per row: method, flags, mean and std per band (fractions), the paper's figures (fractions)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    header = ["method", "unsupervised", "supervised"]
    header += [f"ap_{band}" for band in BANDS] + [f"ap_{band}_std" for band in BANDS]
    header += ["n_seeds"] + [f"paper_ap_{band}" for band in TABLE_BANDS]
    writer.writerow(header)
    for row in rows:
        mean, std = row.ap_mean(), row.ap_std()
        paper = row.paper_ap() or {}
        writer.writerow(
            [row.method, int(row.unsupervised), int(row.supervised)]
            + ["" if mean[b] is None else f"{mean[b]:.4f}" for b in BANDS]
            + ["" if std[b] is None else f"{std[b]:.4f}" for b in BANDS]
            + [len(row.seed_metrics)]
            + ["" if b not in paper else f"{paper[b]:.3f}" for b in TABLE_BANDS]
        )
    return buffer.getvalue()
