"""The printed table (AP in percent, like the paper's Table 1), metrics.json (write and read) and problems.txt."""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from zendar_dataset.atomic_files import json_text, prepare_out_dir, write_text_atomic
from zendar_dataset.errors import ZendarError
from zendar_dataset.eval.bootstrap import distinct_resamples
from zendar_dataset.eval.protocol import BANDS_M, MIN_DISTINCT_RESAMPLES, bootstrap_unit_text
from zendar_dataset.eval.records import MetricsRecord, as_metrics_record

METRICS_FILENAME = "metrics.json"
PROBLEMS_FILENAME = "problems.txt"
#: Every file ``zendar-eval --out DIR`` may write into DIR.
OUTPUT_NAMES = (METRICS_FILENAME, PROBLEMS_FILENAME, *(f"pr_{band}.png" for band in BANDS_M))


def format_percent(value: float | None) -> str:
    """A fraction in [0, 1] as a percentage with one decimal, ``n/a`` for None."""
    return "n/a" if value is None else f"{100.0 * value:.1f}"


def format_table(metrics: MetricsRecord | Mapping[str, Any]) -> str:
    """A plain-text table of AP per band (percent) with GT/TP/FP counts.

    Parameters
    ----------
    metrics
        The record returned by :func:`zendar_dataset.eval.evaluate_record`, or the structure
        returned by :func:`zendar_dataset.eval.evaluate`.

    Returns
    -------
    str
        Several lines, no trailing newline.
    """
    record = as_metrics_record(metrics)
    header = [f"method: {record.meta.get('method', '(no meta.method)')}"]
    if record.split is not None:
        header.append(f"split: {record.split}")
    header.append(f"{record.n_frames} frames, {record.n_scenes} scenes")
    lines = [" | ".join(header)]
    if record.partial:
        lines.append(
            f"PARTIAL evaluation: {record.n_frames} of {record.n_frames_ground_truth} "
            "ground-truth frames (only frames present in the predictions)"
        )
    bootstrap = record.bootstrap
    columns = f"{'band':<5} {'range [m]':<10} {'AP [%]':>7}"
    if bootstrap:
        columns += f"  {'95% CI [%]':<14}"
    columns += f" {'GT':>8} {'TP':>8} {'FP':>8}"
    lines += [columns, "-" * len(columns)]
    for band, (low_m, high_m) in BANDS_M.items():
        row = f"{band:<5} {f'[{low_m:g}, {high_m:g})':<10} {format_percent(record.ap[band]):>7}"
        if bootstrap:
            interval = bootstrap[band]
            text = (
                "n/a"
                if interval.low is None
                else f"[{format_percent(interval.low)}, {format_percent(interval.high)}]"
            )
            row += f"  {text:<14}"
        counts = record.counts[band]
        row += f" {counts.gt:>8} {counts.tp:>8} {counts.fp:>8}"
        lines.append(row)
    if any(value is None for value in record.ap.values()):
        lines.append("n/a: the band has no ground truth")
    if bootstrap:
        n = max(interval.n for interval in bootstrap.values())
        lines.append(f"95% CI: percentile bootstrap over up to {n} {bootstrap_unit_text(record.protocol)} resamples per band")
        # Time blocks record how many there were; scenes are the metrics' n_scenes.
        blocks = record.protocol.get("bootstrap", {}).get("n_units")
        by_blocks = isinstance(blocks, int) and not isinstance(blocks, bool)
        n_units = blocks if by_blocks else record.n_scenes
        distinct = distinct_resamples(n_units)
        if 1 < n_units and distinct < MIN_DISTINCT_RESAMPLES:
            lines.append(
                f"   (only {distinct} distinct resamples of {n_units} units, fewer than "
                f"{MIN_DISTINCT_RESAMPLES}: the interval is the spread of a few values; "
                "more scenes, or --bootstrap-block-s, give more units)"
            )
        if n_units < 2:
            lines.append("   (one time block: resampling cannot show any spread; the interval is a point)"
                         if by_blocks else
                         "   (one scene: resampling scenes cannot show scene-to-scene spread; the interval is a point)")
    return "\n".join(lines)


def write_problems(problems: list[str], out_dir: str | os.PathLike) -> Path:
    """Write every problem, one per line, to ``out_dir/problems.txt`` (atomic); returns the path."""
    path = prepare_out_dir(out_dir) / PROBLEMS_FILENAME
    write_text_atomic(path, "".join(f"{problem}\n" for problem in problems))
    return path


def write_metrics(metrics: MetricsRecord | Mapping[str, Any], out_dir: str | os.PathLike) -> Path:
    """Write ``metrics`` (a record or its ``to_json()``) as ``out_dir/metrics.json`` (strict JSON,
    atomic); returns the path."""
    document = metrics.to_json() if isinstance(metrics, MetricsRecord) else metrics
    path = prepare_out_dir(out_dir) / METRICS_FILENAME
    write_text_atomic(path, json_text(document))
    return path


def read_metrics(path: str | os.PathLike) -> MetricsRecord:
    """The record held by a ``metrics.json`` (as :func:`write_metrics` writes it).

    Raises
    ------
    ZendarError
        Naming the file when it cannot be read, is not JSON, or is not the evaluator's metrics
        (then listing every missing or wrong member).
    """
    try:
        document = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ZendarError(f"{path}: cannot be read as the evaluator's metrics ({exc})") from None
    return MetricsRecord.from_json(document, source=str(path))
