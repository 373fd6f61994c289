"""Where the automatic labels go wrong, per range band: which points they call moving off the labelled
cars, and which points of the labelled cars they miss.

    python -m zendar_baselines.labels.autolabel_errors ROOT [--split train] [--threshold-db DB]

The points are the automatic labels' own (:func:`zendar_baselines.labels.masks.auto_label_points`:
every CFAR peak of every cube, with its DOA, SAR value and cluster), each read against the mask the
automatic labels' quality is measured with (``zendar_baselines.labels.quality.QUALITY_REFERENCE``:
the CFAR-gated manual-label mask, at the point's cell), banded by the point's range from the ego.

- *Called moving off the cars*: points of all-dynamic clusters (the seeds of MOVING segments) whose
  cell the reference leaves background. Counted with those whose Doppler says they move over the
  ground (``|residual|`` above :data:`~zendar_baselines.labels.masks.DEFAULT_MAX_VELOCITY_ERROR_MPS`:
  returns of moving objects outside every labelled box, such as mirror ghosts), those alone in their
  cluster, and their median distance to the nearest labelled box centre.
- *Missed on the cars*: points on the reference's MOVING cells, and the share the SAR test calls
  dynamic, by the CFAR peak's score (its power over the CA-CFAR noise estimate): weak peaks beside a
  car's strong ones read the strong ones' bright SAR smear.
"""

from __future__ import annotations

import argparse
import sys
from collections import defaultdict

import numpy as np

from zendar_dataset.cli.common import run_cli
from zendar_dataset.errors import ZendarError
from zendar_dataset.eval.protocol import BANDS_M, RANGE_BANDS
from zendar_dataset.format.reader import open_dataset
from zendar_dataset.sar.frames import SarFrames

from zendar_baselines.labels.mask_classes import BACKGROUND, MOVING
from zendar_baselines.labels.masks import (
    DEFAULT_MAX_VELOCITY_ERROR_MPS,
    MaskParams,
    auto_label_points,
    cubes_with_boxes,
    label_mask,
)
from zendar_baselines.labels.quality import QUALITY_REFERENCE

#: CFAR scores (linear power over the noise estimate) that split the on-car points into rows.
SCORE_EDGES = (0.0, 1e2, 1e3, 1e4, np.inf)


def point_table(root: str, split: str, params: MaskParams, reference: MaskParams) -> dict[str, np.ndarray]:
    """Every automatic-label point of ``split``'s labelled scenes: ``range_m``, ``reference`` (the
    reference mask's class at its cell), ``moving`` (all-dynamic cluster), ``dynamic`` (the SAR test's
    verdict), ``residual_mps``, ``cluster_size``, ``score`` and ``box_distance_m`` (to the nearest
    labelled box centre; inf without a box)."""
    index = open_dataset(root)
    columns: dict[str, list[np.ndarray]] = defaultdict(list)
    for scene_id in index.scene_ids(split):
        with index.open_scene(scene_id) as reader:
            labels = reader.labels()
            if labels is None:
                continue
            sar, poses = SarFrames(reader), reader.ego_poses()
            for radar in reader.sensors("radar"):
                calibration = reader.calibration.sensors[radar]
                for cube_ns, cube, boxes in cubes_with_boxes(reader, radar, labels, poses):
                    labelled = auto_label_points(cube, cube_ns, calibration, poses, sar, params)
                    points = labelled.points
                    xy = points.points_ego[:, :2]
                    centres = np.stack([boxes.x, boxes.y], axis=1)
                    columns["range_m"].append(np.hypot(xy[:, 0], xy[:, 1]))
                    columns["reference"].append(label_mask(cube, cube_ns, calibration, poses, boxes, reference)[
                        points.range_bin, points.doppler_bin])
                    columns["moving"].append(labelled.moving)
                    columns["dynamic"].append(points.dynamic)
                    columns["residual_mps"].append(points.residual_mps)
                    columns["cluster_size"].append(labelled.cluster_size)
                    columns["score"].append(points.score)
                    columns["box_distance_m"].append(
                        np.linalg.norm(xy[:, None] - centres[None], axis=-1).min(axis=1) if len(boxes)
                        else np.full(len(points), np.inf))
    if not columns:
        raise ZendarError(f"{root}: split {split!r} has no scene with labels to read the automatic labels against")
    return {name: np.concatenate(parts) for name, parts in columns.items()}


def error_report(table: dict[str, np.ndarray]) -> str:
    """The two tables of the module docstring, as markdown."""
    lines = ["| band | called moving | on a car | reference uncertain | off the cars | of them moving by Doppler "
             "| alone in their cluster | median distance to a box (m) |", "|---|--:|--:|--:|--:|--:|--:|--:|"]
    missed = ["| band | CFAR score | points on cars | called dynamic |", "|---|---|--:|--:|"]
    for band in RANGE_BANDS:
        low_m, high_m = BANDS_M[band]
        in_band = (table["range_m"] >= low_m) & (table["range_m"] < high_m)
        called = in_band & table["moving"]
        off = called & (table["reference"] == BACKGROUND)
        distance = table["box_distance_m"][off]
        lines.append(
            f"| {band} | {called.sum()} | {(called & (table['reference'] == MOVING)).sum()} "
            f"| {(called & (table['reference'] != MOVING) & ~off).sum()} | {off.sum()} "
            f"| {(off & (np.abs(table['residual_mps']) > DEFAULT_MAX_VELOCITY_ERROR_MPS)).sum()} "
            f"| {(off & (table['cluster_size'] == 1)).sum()} "
            f"| {np.median(distance[np.isfinite(distance)]) if np.isfinite(distance).any() else float('nan'):.1f} |")
        on_car = in_band & (table["reference"] == MOVING)
        for low, high in zip(SCORE_EDGES[:-1], SCORE_EDGES[1:]):
            rows = on_car & (table["score"] >= low) & (table["score"] < high)
            share = f"{table['dynamic'][rows].mean():.0%}" if rows.any() else "-"
            missed.append(f"| {band} | [{low:g}, {high:g}) | {rows.sum()} | {share} |")
    return "\n".join(["Called moving (points of all-dynamic clusters) against the reference mask:", *lines, "",
                      "Points on the reference's MOVING cells, by CFAR score, and the share the SAR test calls dynamic:",
                      *missed])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("root", help="dataset root")
    parser.add_argument("--split", default="train", help="split to read (default: train)")
    parser.add_argument("--threshold-db", type=float, default=None, help="the SAR test's threshold (default: the package's)")
    args = parser.parse_args(argv)
    params = MaskParams().with_sar_threshold(args.threshold_db)
    return run_cli(lambda: print(error_report(point_table(args.root, args.split, params, QUALITY_REFERENCE))))


if __name__ == "__main__":
    sys.exit(main())
