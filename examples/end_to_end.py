"""End to end: load a split, find moving cars in the radar cubes, write predictions, score them.

    python examples/end_to_end.py ROOT [--split test] [--out DIR]

A dataset to try it on: ``zendar-data synth /tmp/demo --profile demo --scenes 2``.

The detector here is a deliberately simple classical one, written to show the
package's pieces working together; it is *not* the paper's baseline (CFAR +
SAR-mask auto-labels + CNN, see ``baselines/``); its functions live in
``zendar_dataset.detection.classical``. Per SAR frame it:

1. takes each radar's latest range-Doppler cube (the loader synchronises them);
2. finds peaks with CA-CFAR and their azimuth with Bartlett beamforming;
3. keeps the detections whose radial velocity differs from what a static world
   would show at that azimuth, given the radar's own velocity from the tracklog;
4. clusters the moving points (DBSCAN) and reports one car per cluster.

Outputs in ``--out``: ``predictions.json`` (the evaluator's format) and
``metrics.json``; both are replaced when the script runs again.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from torch.utils.data import DataLoader

from zendar_dataset import ZendarDataset
from zendar_dataset.detection.classical import cluster_cars, moving_points
from zendar_dataset.detection.locate import mount_velocity_ego  # noqa: F401 (re-exported)
from zendar_dataset.cli.common import run_cli
from zendar_dataset.eval import evaluate
from zendar_dataset.atomic_files import prepare_out_dir, write_json_atomic
from zendar_dataset.eval.report import format_table, write_metrics
from zendar_dataset.format import frame_id
from zendar_dataset.geometry.frames import EgoPoses


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("root", help="dataset root (directory or fsspec URL)")
    parser.add_argument("--split", default="test", help="split to run on (default: test)")
    parser.add_argument("--out", default="end_to_end_out", help="directory for predictions.json and metrics.json")
    args = parser.parse_args(argv)
    return run_cli(lambda: run(args.root, args.split, Path(args.out)))


def run(root: str, split: str, out: Path) -> int:
    # Step 1: one item per SAR frame, with each radar's latest cube, the ego pose and labels.
    ds = ZendarDataset(root, split, streams=("radar", "sar", "tracklog", "labels"), reference="sar", cube_window=1)
    print(ds)
    report = ds.sync_report()  # one row per scene and stream: matches, drops, time residuals
    worst = report.loc[report["abs_dt_max_ns"].idxmax()]
    print(f"[1] sync: {report['stream'].nunique()} streams over {len(ds)} items: "
          f"{report['matched'].sum()} matched, {report['missing'].sum()} missing, "
          f"{report['dropped'].sum()} frames dropped; largest |dt| {worst.abs_dt_max_ns / 1e6:.1f} ms ({worst.stream})")
    loader = DataLoader(ds, batch_size=4, num_workers=2, collate_fn=ds.collate)

    # Step 2: moving-object detection per frame.
    results: dict[str, list[dict[str, float]]] = {}
    poses: dict[str, EgoPoses] = {}
    n_points = n_cars_labelled = 0
    for batch in loader:
        for b, frame in enumerate(batch["frame_id"]):
            scene_id = batch["scene_id"][b]
            if scene_id not in poses:
                poses[scene_id] = ds.ego_poses(scene_id)
            sensors = ds.scene_reader(scene_id).calibration.sensors
            frame_ns = int(batch["timestamp_ns"][b])
            points, snrs = [], []
            for radar, window in batch["radar"].items():  # front_left, front_right
                cube_ns = int(window["timestamp_ns"][b, -1])
                points_ego, snr = moving_points(window["cube"][b, -1].numpy(), cube_ns, sensors[radar], poses[scene_id])
                # Ego frame at the cube's time -> ego frame at the SAR frame's time (the evaluator's frame).
                points.append(poses[scene_id].ecef_to_ego(poses[scene_id].ego_to_ecef(points_ego, cube_ns), frame_ns))
                snrs.append(snr)
            points_ego, snr = np.concatenate(points), np.concatenate(snrs)
            results[frame] = cluster_cars(points_ego, snr)
            n_points += len(points_ego)
            # Labels collate to {field: [per-item tensor]}, or a list holding None where withheld.
            labels = batch["labels"]
            n_cars_labelled += len(labels["x"][b]) if isinstance(labels, dict) else 0
    # Frames the loader left out (e.g. a radar window it could not fill) still need an entry.
    for scene_id in ds.scene_ids:
        for timestamp_ns in ds.scene_reader(scene_id).timestamps(ds.sync_table(scene_id).reference):
            results.setdefault(frame_id(scene_id, int(timestamp_ns)), [])
    n_predictions = sum(len(cars) for cars in results.values())
    print(f"[2] detect: {len(results)} frames, {n_points} moving radar points -> {n_predictions} predicted cars "
          f"({n_cars_labelled} labelled)")

    # Step 3: predictions.json in the evaluator's format, written atomically, then scored.
    out = prepare_out_dir(out)
    predictions = {"meta": {"method": "cfar-doppler-dbscan (examples/end_to_end.py)"}, "results": results}
    path = out / "predictions.json"
    write_json_atomic(path, predictions)
    print(f"[3] wrote {path}")
    metrics = evaluate(path, root, split=split)
    print(format_table(metrics))
    print(f"wrote {write_metrics(metrics, out)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
