"""Precision-recall plots per band (matplotlib, Agg canvas: no display needed)."""

from __future__ import annotations

import io
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from zendar_dataset.errors import ZendarError
from zendar_dataset.eval.protocol import BANDS_M
from zendar_dataset.eval.records import MetricsRecord, as_metrics_record
from zendar_dataset.atomic_files import prepare_out_dir, write_bytes_atomic


def pr_figure(metrics: MetricsRecord | Mapping[str, Any], band: str) -> Figure:
    """The precision-recall figure of one band (Agg canvas attached).

    Shows the measured precision at each distinct score (dots) and the precision envelope
    whose area is the AP (step line); the legend sits below the axes, never over a curve.

    Parameters
    ----------
    metrics
        The record returned by :func:`zendar_dataset.eval.evaluate_record`, or the structure
        returned by :func:`zendar_dataset.eval.evaluate`; with its precision-recall curves.
    band
        A key of ``BANDS_M``.
    """
    low_m, high_m = BANDS_M[band]
    record = as_metrics_record(metrics)
    if record.pr_curves is None:
        raise ZendarError("metrics without 'pr_curves': no precision-recall curve to draw")
    method = record.meta.get("method", "")
    curve = record.pr_curves[band]
    ap = record.ap[band]
    # Constrained layout makes room for the legend below the axes.
    figure = Figure(figsize=(5, 4.4), dpi=100, layout="constrained")
    FigureCanvasAgg(figure)
    axes = figure.add_subplot()
    if ap is None:
        axes.text(0.5, 0.5, "no ground truth in this band", ha="center", va="center")
        title_ap = "AP n/a"
    elif not curve.recall:
        axes.text(0.5, 0.5, "no detections in this band", ha="center", va="center")
        title_ap = f"AP {100.0 * ap:.1f}%"
    else:
        recall = [0.0, *curve.recall]
        envelope = [*curve.precision_envelope[:1], *curve.precision_envelope]
        axes.step(recall, envelope, where="pre", label="precision envelope")
        axes.plot(curve.recall, curve.precision, ".", markersize=3, label="precision")
        axes.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2, frameon=False)
        title_ap = f"AP {100.0 * ap:.1f}%"
    axes.set_xlim(0.0, 1.0)
    axes.set_ylim(0.0, 1.02)
    axes.set_xlabel("recall")
    axes.set_ylabel("precision")
    # Method names can be long: on their own line, shortened to fit the figure's width.
    method_line = method if len(method) <= 48 else method[:47] + "…"
    axes.set_title(f"{method_line}\n{band} [{low_m:g}, {high_m:g}) m: {title_ap}".strip(), fontsize=10)
    axes.grid(alpha=0.3)
    return figure


def plot_pr_curves(metrics: MetricsRecord | Mapping[str, Any], out_dir: str | os.PathLike) -> list[Path]:
    """Write ``out_dir/pr_<band>.png`` for every band (see :func:`pr_figure`).

    Parameters
    ----------
    metrics
        As for :func:`pr_figure`.
    out_dir
        Created if missing.

    Returns
    -------
    list of pathlib.Path
        The files written, in band order.
    """
    record = as_metrics_record(metrics)
    out = prepare_out_dir(out_dir)
    written = []
    for band in BANDS_M:
        buffer = io.BytesIO()
        pr_figure(record, band).savefig(buffer, format="png")
        path = out / f"pr_{band}.png"
        write_bytes_atomic(path, buffer.getvalue())
        written.append(path)
    return written
