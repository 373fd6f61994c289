"""The pictures a researcher looks at first: precision-recall per band with every method on one
plot, a bird's-eye view of a test frame (SAR image, ground truth, each method's detections), and the
CNN rows' training curves (train and validation loss per epoch).

matplotlib on the Agg canvas (no display needed); files are written atomically.
"""

from __future__ import annotations

import io
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Polygon

from zendar_dataset.atomic_files import write_bytes_atomic
from zendar_dataset.errors import ZendarError
from zendar_dataset.eval.protocol import BANDS_M
from zendar_dataset.eval.records import MetricsRecord, as_metrics_record
from zendar_dataset.format import frame_id
from zendar_dataset.format.reader import DatasetIndex
from zendar_dataset.geometry.frames import sar_pixel_to_ecef
from zendar_dataset.sar.frames import SarFrames

from zendar_baselines.bench.run_directory import read_json
from zendar_baselines.fingerprints import dataset_index

_MARKERS = ("o", "s", "^", "v", "D", "P", "X", "*")


def _save_png(figure: Figure, path: Path) -> Path:
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png")
    write_bytes_atomic(path, buffer.getvalue())
    return path


def pr_comparison_figure(curves: list[tuple[str, MetricsRecord | Mapping[str, Any]]], band: str) -> Figure:
    """Precision envelopes of several methods in one band.

    Parameters
    ----------
    curves
        ``(label, metrics)`` per method, ``metrics`` as returned by ``zendar_dataset.eval.evaluate_record``
        (or ``evaluate``).
    band
        A key of ``BANDS_M``.
    """
    low_m, high_m = BANDS_M[band]
    figure = Figure(figsize=(10.0, 5.2), dpi=100, layout="constrained")
    FigureCanvasAgg(figure)
    axes = figure.add_subplot()
    for index, (label, metrics) in enumerate(curves):
        record = as_metrics_record(metrics)
        curve, ap = record.pr_curves[band], record.ap[band]
        text = f"{label} (AP n/a)" if ap is None else f"{label} (AP {100 * ap:.1f})"
        if not curve.recall:
            axes.plot([], [], label=text + ", no detections")
            continue
        recall = [0.0, *curve.recall]
        envelope = [*curve.precision_envelope[:1], *curve.precision_envelope]
        axes.step(recall, envelope, where="pre", label=text, marker=_MARKERS[index % len(_MARKERS)],
                  markevery=max(1, len(recall) // 8), markersize=4)
    axes.set_xlim(0.0, 1.0)
    axes.set_ylim(0.0, 1.02)
    axes.set_xlabel("recall")
    axes.set_ylabel("precision (envelope)")
    axes.set_title(f"moving cars, {band} [{low_m:g}, {high_m:g}) m", fontsize=10)
    axes.grid(alpha=0.3)
    axes.legend(loc="center left", bbox_to_anchor=(1.02, 0.5), ncol=1, frameon=False, fontsize=8)
    return figure


def write_pr_comparisons(curves: list[tuple[str, MetricsRecord | Mapping[str, Any]]], out_dir: Path) -> list[Path]:
    """``out_dir/pr_<band>.png`` for every band (see :func:`pr_comparison_figure`)."""
    return [_save_png(pr_comparison_figure(curves, band), out_dir / f"pr_{band}.png") for band in BANDS_M]


#: Colour of each training phase in the curves figure.
PHASE_COLOURS = {"supervised": "C0", "pretrain": "C1", "fine-tune": "C2"}


def _model_of(row_key: str) -> str:
    # Row keys are "<model>-supervised" or "<model>-pretrained".
    return row_key.rsplit("-", 1)[0]


def loss_curves_figure(curves: list[Mapping[str, Any]]) -> Figure:
    """Train (dashed) and validation (solid) loss per epoch, one panel per architecture.

    A pretrained row's fine-tuning epochs follow its pretraining epochs on the same axis; a star marks
    each phase's chosen epoch (the lowest validation loss). Every seed is drawn (thinner after the first).

    Parameters
    ----------
    curves
        ``curves.json`` documents (:func:`zendar_baselines.bench.steps.write_training_records`): ``row``,
        ``seed`` and ``phases``, each phase with ``phase``, ``best_epoch`` and ``epochs`` of
        ``{"epoch", "train", "validation"}`` (losses per labelled cell; None where not finite).

    Raises
    ------
    ZendarError
        When ``curves`` is empty.
    """
    models = list(dict.fromkeys(_model_of(record["row"]) for record in curves))
    if not models:
        raise ZendarError("loss_curves_figure: no training curves to draw")
    figure = Figure(figsize=(4.0 * len(models) + 2.0, 4.2), dpi=100, layout="constrained")
    FigureCanvasAgg(figure)
    panels = figure.subplots(1, len(models), squeeze=False, sharey=True)[0]
    legend: dict[str, Any] = {}
    for axes, model in zip(panels, models):
        records = sorted((r for r in curves if _model_of(r["row"]) == model), key=lambda r: (r["row"], r["seed"]))
        first_seed = min(record["seed"] for record in records)
        for record in records:
            width, alpha = (1.6, 1.0) if record["seed"] == first_seed else (0.8, 0.45)
            offset = 0
            for phase in record["phases"]:
                colour = PHASE_COLOURS.get(phase["phase"], "C3")
                epochs = [offset + entry["epoch"] for entry in phase["epochs"]]
                train = [np.nan if entry["train"] is None else entry["train"] for entry in phase["epochs"]]
                validation = [np.nan if entry["validation"] is None else entry["validation"] for entry in phase["epochs"]]
                line, = axes.plot(epochs, train, linestyle="--", color=colour, linewidth=width, alpha=alpha)
                legend.setdefault(f"{phase['phase']}, train", line)
                line, = axes.plot(epochs, validation, linestyle="-", color=colour, linewidth=width, alpha=alpha)
                legend.setdefault(f"{phase['phase']}, validation", line)
                best = phase["best_epoch"]
                if 1 <= best <= len(validation):
                    star, = axes.plot([offset + best], [validation[best - 1]], marker="*", markersize=10, color=colour,
                                      linestyle="none", alpha=alpha)
                    legend.setdefault("epoch chosen", star)
                offset = epochs[-1] if epochs else offset
        axes.set_title(model, fontsize=10)
        axes.set_xlabel("epoch (fine-tuning after pretraining)")
        axes.set_yscale("log")
        axes.grid(alpha=0.3, which="both")
    panels[0].set_ylabel("masked BCE per labelled cell")
    figure.legend(list(legend.values()), list(legend), loc="outside right center", frameon=False, fontsize=8)
    return figure


def write_loss_curves(path: Path, row_dirs: list[Path]) -> Path | None:
    """``path`` (PNG): :func:`loss_curves_figure` of every ``<row_dir>/seed-*/curves.json``; None without rows.

    Raises
    ------
    ZendarError
        When a row directory holds no seed's curves.
    """
    curves = []
    for row_dir in row_dirs:
        files = sorted(row_dir.glob("seed-*/curves.json"))
        if not files:
            raise ZendarError(f"{row_dir}: no seed-*/curves.json to draw")
        curves.extend(read_json(file) for file in files)
    if not curves:
        return None
    return _save_png(loss_curves_figure(curves), path)


def _box_corners(car: dict[str, float]) -> np.ndarray:
    c, s = np.cos(car["yaw"]), np.sin(car["yaw"])
    half = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]]) * [car["length"] / 2, car["width"] / 2]
    return half @ np.array([[c, s], [-s, c]]) + [car["x"], car["y"]]


def compose_layers(
    sar_layers: list[tuple[np.ndarray, np.ndarray]], extent_m: float, cell_m: float | None = None
) -> tuple[np.ndarray, float]:
    """Every radar's SAR image on one ego-frame grid, the brightest value per cell.

    Drawing one image over another would hide the first wherever they overlap (both radars see the
    lane ahead); the maximum keeps what either radar shows there.

    Parameters
    ----------
    sar_layers
        As :func:`bev_figure`'s.
    extent_m
        The grid spans x in [-extent_m, extent_m] and y in [-extent_m, extent_m] (ego frame, metres).
    cell_m
        Cell size in metres; by default √2 times the coarsest spacing between neighbouring pixels
        of the layers: a cell that wide holds a pixel of a lattice of that spacing however it is
        rotated, so an image leaves no empty cells inside it.

    Returns
    -------
    grid : numpy.ndarray
        ``[N, N]`` float64, ``grid[i, j]`` at x = -extent_m + (i + 0.5) * cell_m and
        y = -extent_m + (j + 0.5) * cell_m; NaN where no image covers the cell.
    cell_m : float
        The cell size used.
    """
    if cell_m is None:
        spacings = [float(np.max(np.hypot(*np.moveaxis(np.diff(xy, axis=axis), -1, 0))))
                    for _, xy in sar_layers for axis in (0, 1) if xy.shape[axis] > 1]
        cell_m = np.sqrt(2.0) * max(spacings, default=1.0)
    n = int(np.ceil(2.0 * extent_m / cell_m))
    grid = np.full((n, n), -np.inf)
    for image_db, xy_ego in sar_layers:
        index = np.floor((xy_ego.reshape(-1, 2) + extent_m) / cell_m).astype(np.int64)
        values = np.asarray(image_db, np.float64).reshape(-1)
        inside = np.all((index >= 0) & (index < n), axis=1) & np.isfinite(values)
        np.maximum.at(grid, (index[inside, 0], index[inside, 1]), values[inside])
    grid[np.isneginf(grid)] = np.nan
    return grid, cell_m


def bev_figure(
    sar_layers: list[tuple[np.ndarray, np.ndarray]],
    ground_truth: list[dict[str, float]],
    detections: dict[str, list[dict[str, float]]],
    title: str,
    extent_m: float = 60.0,
) -> Figure:
    """Bird's-eye view of one frame in its ego frame (x forward, y left), metres.

    Parameters
    ----------
    sar_layers
        Per SAR image: ``image_db [H, W]`` (dB over the image's median) and ``xy_ego [H, W, 2]``,
        the ego-frame position of each pixel centre. Overlapping images are composed per cell
        (:func:`compose_layers`), never drawn one over the other.
    ground_truth
        Labelled cars of the frame: ``x, y, length, width, yaw`` (ego frame, m, rad).
    detections
        Method label → its detections ``{"x", "y", "score"}`` in the frame.
    extent_m
        Half-width of the view; the evaluator's bands end at 60 m.
    """
    figure = Figure(figsize=(13.0, 7.5), dpi=100, layout="constrained")
    FigureCanvasAgg(figure)
    axes = figure.add_subplot()
    mesh = None
    if sar_layers:
        grid, cell_m = compose_layers(sar_layers, extent_m)
        # Plot y to the left as on a map seen from above: horizontal axis = -y, vertical = x.
        mesh = axes.imshow(grid[:, ::-1], cmap="gray", vmin=-10.0, vmax=30.0, origin="lower", interpolation="nearest",
                           extent=(extent_m - grid.shape[1] * cell_m, extent_m, -extent_m, -extent_m + grid.shape[0] * cell_m))
    if mesh is not None:
        figure.colorbar(mesh, ax=axes, label="SAR, dB over the image median", location="left", shrink=0.6)
    for radius in (15.0, 30.0, 60.0):
        angle = np.linspace(-np.pi, np.pi, 256)
        axes.plot(radius * np.sin(angle), radius * np.cos(angle), color="0.6", linewidth=0.6, linestyle=":")
    for index, car in enumerate(ground_truth):
        corners = _box_corners(car)
        axes.add_patch(Polygon(np.c_[-corners[:, 1], corners[:, 0]], closed=True, fill=False, edgecolor="lime",
                               linewidth=1.5, label="ground truth" if index == 0 else None))
    for index, (label, cars) in enumerate(detections.items()):
        if not cars:
            axes.plot([], [], _MARKERS[index % len(_MARKERS)], label=f"{label} (none)")
            continue
        xy = np.array([[car["x"], car["y"]] for car in cars])
        axes.plot(-xy[:, 1], xy[:, 0], _MARKERS[index % len(_MARKERS)], markersize=6, markerfacecolor="none",
                  markeredgewidth=1.4, label=label)
    axes.plot([0.0], [0.0], marker=(3, 0, 0), color="red", markersize=10, label="ego")
    axes.set_xlim(-extent_m, extent_m)
    axes.set_ylim(-10.0, extent_m)
    axes.set_aspect("equal")
    axes.set_xlabel("-y (left of the ego is to the left), m")
    axes.set_ylabel("x (forward), m")
    axes.set_title(title, fontsize=10)
    axes.legend(loc="center left", bbox_to_anchor=(1.02, 0.5), ncol=1, frameon=False, fontsize=8)
    return figure


def write_bev(figure: Figure, path: Path) -> Path:
    """Write a figure of :func:`bev_figure` as PNG, atomically."""
    return _save_png(figure, path)


#: Pixels per side of the SAR image drawn in the bird's-eye figure (subsampled; a figure needs no more).
BEV_PIXELS = 300


def write_bev_figure(path: Path, dataset: DatasetIndex | str | os.PathLike, predictions: dict[str, Path]) -> Path:
    """The test frame with the most labelled cars: SAR images, ground truth, every method's detections.

    ``dataset``: its root, or the dataset already opened; ``predictions``: label -> predictions file.
    """
    index = dataset_index(dataset)
    best: tuple[int, str, int] | None = None
    for scene_id in index.scene_ids("test"):
        labels = index.open_scene(scene_id).labels()
        stamps, counts = np.unique(labels["timestamp_ns"], return_counts=True)
        if stamps.size and (best is None or counts.max() > best[0]):
            best = (int(counts.max()), scene_id, int(stamps[np.argmax(counts)]))
    if best is None:
        raise ZendarError(f"{index.root}: the test split has no labelled car to draw")
    _, scene_id, frame_ns = best
    with index.open_scene(scene_id) as reader:
        poses = reader.ego_poses()
        sar = SarFrames(reader)
        layers = []
        for sensor in sar.sensors:
            frame = sar.frame_index(sensor, frame_ns)
            if frame is None:
                continue
            image_db, _ = sar.image_db(sensor, frame)
            step = max(1, max(image_db.shape) // BEV_PIXELS)
            i, j = np.meshgrid(np.arange(0, image_db.shape[0], step), np.arange(0, image_db.shape[1], step), indexing="ij")
            points_ecef = sar_pixel_to_ecef(i, j, sar.origin[sensor][frame], sar.di[sensor][frame], sar.dj[sensor][frame])
            xy_ego = poses.ecef_to_ego(points_ecef.reshape(-1, 3), frame_ns)[:, :2].reshape(*i.shape, 2)
            layers.append((image_db[::step, ::step], xy_ego))
        labels = reader.labels()
    rows = labels["timestamp_ns"] == frame_ns
    truth = [{name: float(labels[name][k]) for name in ("x", "y", "length", "width", "yaw")} for k in np.flatnonzero(rows)]
    frame = frame_id(scene_id, frame_ns)
    detections = {label: read_json(file)["results"].get(frame, []) for label, file in predictions.items()}
    figure = bev_figure(layers, truth, detections, f"{frame}: SAR, ground truth (boxes) and detections")
    return write_bev(figure, path)
