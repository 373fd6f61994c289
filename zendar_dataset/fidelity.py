"""The fidelity report of a dataset (``zendar-data fidelity``): do labels, radar and SAR agree?

For every SAR frame (the labels' frames) of the chosen scenes it measures, per range band of the
evaluator (near [0, 15), mid [15, 30), far [30, 60) m of r = sqrt(x² + y²) in the ego frame):

- labels per band, the share of labels inside a radar's field of view (``fov_azimuth_deg`` of the
  calibration) and labels behind the ego's front bumper;
- for a simulated dataset whose truth can be rebuilt (``simulation.json`` + seed,
  :func:`zendar_dataset.sim.scene.build_scene`): the moving cars an annotator would label from the
  radar data (:func:`zendar_dataset.sim.labels.annotatable_cars`) that carry no label;
- the share of labelled cars within 60 m whose centre lies inside a SAR image of the frame;
- the CFAR detections of each radar's latest cube at or before the frame, split into detections on moving cars (inside a
  car's box grown by :data:`ON_CAR_MARGIN_M`; truth boxes where the truth is known, else labels)
  and static ones, and how well two tests separate them (ROC AUC, ``sklearn.metrics.roc_auc_score``):
  the paper's SAR mask (a detection projecting onto a dark SAR pixel is moving, §2.3), read exactly as
  the baselines read it (:func:`zendar_dataset.detection.static_scene.sar_db_at`: the brightest
  pixel near the point in the SAR frame nearest the cube's time within 150 ms, minus the
  detection's range-Doppler SNR), and the plain
  Doppler test (measured radial velocity against a static point's at that azimuth);
- the CFAR detection rate (labelled cars with at least one CFAR detection on them) and the AP of
  :mod:`zendar_dataset.detection.classical` under the official evaluator.
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from sklearn.metrics import roc_auc_score

from zendar_dataset.detection.boxes import ON_CAR_MARGIN_M, LabelBoxes
from zendar_dataset.detection.classical import cluster_cars, radar_points
from zendar_dataset.detection.scene import latest_cube
from zendar_dataset.detection.static_scene import SarTestParams, sar_db_at
from zendar_dataset.errors import ZendarError
from zendar_dataset.eval import evaluate_record
from zendar_dataset.eval.protocol import ALL_BAND, BANDS_M, RANGE_BANDS
from zendar_dataset.format import frame_id
from zendar_dataset.format.reader import SceneReader, open_dataset
from zendar_dataset.geometry.frames import ego_T_sensor
from zendar_dataset.radar import FmcwParams
from zendar_dataset.sar.frames import SarFrames
from zendar_dataset.sim import ego as ego_model
from zendar_dataset.sim.labels import MIN_SPEED_MPS, annotatable_cars, radar_views
from zendar_dataset.sim.profiles import PROFILES
from zendar_dataset.sim.scene import build_scene
from zendar_dataset.sim.rotate import unrotate

SIMULATION_JSON = "simulation.json"
_SCENE_INDEX = re.compile(r"^scene-(\d+)$")


def _band(r_m: np.ndarray) -> np.ndarray:
    """Band name per range (``""`` beyond 60 m)."""
    out = np.full(np.shape(r_m), "", dtype=object)
    for name in RANGE_BANDS:
        low, high = BANDS_M[name]
        out[(r_m >= low) & (r_m < high)] = name
    return out


@dataclass
class _Tally:
    """Everything counted over the frames, turned into the report at the end."""

    labels: dict[str, int] = field(default_factory=lambda: dict.fromkeys((*RANGE_BANDS, "beyond"), 0))
    labels_in_fov: int = 0
    labels_with_fov_known: int = 0
    labels_behind_ego: int = 0
    annotatable: int = 0
    annotatable_unlabelled: int = 0
    sar_covered: dict[str, int] = field(default_factory=lambda: dict.fromkeys(RANGE_BANDS, 0))
    sar_checked: dict[str, int] = field(default_factory=lambda: dict.fromkeys(RANGE_BANDS, 0))
    detected: dict[str, int] = field(default_factory=lambda: dict.fromkeys(RANGE_BANDS, 0))
    band: list = field(default_factory=list)  # per CFAR detection
    on_car: list = field(default_factory=list)
    sar_db: list = field(default_factory=list)
    doppler_mps: list = field(default_factory=list)
    predictions: dict[str, list] = field(default_factory=dict)
    ground_truth: dict[str, list] = field(default_factory=dict)
    frames: int = 0


def _simulation_truth(root: str) -> Callable[[str], Any] | None:
    """A function scene_id -> SceneTruth when ``root`` is a simulated dataset whose truth can be rebuilt."""
    path = os.path.join(str(root), SIMULATION_JSON)
    if not os.path.isfile(path):
        return None
    with open(path, encoding="utf-8") as handle:
        settings = json.load(handle)
    recorded = settings.get("profile", {})
    profile = PROFILES.get(recorded.get("name"))
    # `synth --duration-s` records the named profile with another scene length.
    if profile is not None and recorded.get("scene_duration_s") != profile.scene_duration_s:
        try:
            profile = profile.with_duration(recorded.get("scene_duration_s"))
        except ZendarError:
            return None
    # The truth is only the truth when this simulator would draw the same scenes.
    if profile is None or json.loads(json.dumps(profile.to_json())) != recorded:
        return None
    seed = int(settings["seed"])

    def truth(scene_id: str):
        match = _SCENE_INDEX.match(scene_id)
        return build_scene(profile, seed, int(match.group(1))) if match else None

    return truth


def _in_boxes(points_xy: np.ndarray, center: np.ndarray, length: np.ndarray, width: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """``[P, B]`` bool: points inside boxes grown by :data:`ON_CAR_MARGIN_M` (ego frame)."""
    n = len(length)
    boxes = LabelBoxes(0, center[:, 0], center[:, 1], length, width, yaw, np.zeros(n), np.zeros(n))
    return boxes.contains(points_xy, ON_CAR_MARGIN_M)


def _scene(reader: SceneReader, truth, tally: _Tally, max_frames: int | None) -> None:
    labels = reader.labels()
    sar = SarFrames(reader)
    if not sar.sensors or labels is None:
        return
    calibration = reader.calibration
    radars = reader.sensors("radar")
    poses = reader.ego_poses()
    radar_times = {r: reader.timestamps(f"radar/{r}") for r in radars}
    cubes = {r: reader.array(f"radar/{r}/cube") for r in radars}
    mounts = {r: ego_T_sensor(calibration.sensors[r]) for r in radars}
    fov = {r: getattr(calibration.sensors[r], "fov_azimuth_deg", None) for r in radars}
    views = None
    if truth is not None:
        cube_shape = cubes[radars[0]].shape  # [N, R, D, A]
        reach_m = FmcwParams.from_calibration(calibration.sensors[radars[0]], n_samples=cube_shape[1], n_chirps=cube_shape[2]).max_range_m
        views = radar_views(reach_m)
    frames = sar.timestamps[sar.sensors[0]]
    if max_frames is not None:
        frames = frames[:max_frames]
    for stamp in frames.tolist():
        tally.frames += 1
        rows = np.flatnonzero(labels["timestamp_ns"] == stamp)
        x, y = labels["x"][rows], labels["y"][rows]
        r = np.hypot(x, y)
        bands = _band(r)
        for b in RANGE_BANDS:
            tally.labels[b] += int(np.count_nonzero(bands == b))
        tally.labels["beyond"] += int(np.count_nonzero(bands == ""))
        tally.labels_behind_ego += int(np.count_nonzero(x <= 0.0))
        # Field of view of each label's centre.
        if rows.size and all(fov[radar] is not None for radar in radars):
            in_view = np.zeros(rows.size, bool)
            for radar in radars:
                local = mounts[radar].inverse().transform_points(np.stack([x, y, np.full_like(x, mounts[radar].translation[2])], axis=1))
                azimuth = np.degrees(np.arctan2(local[:, 1], local[:, 0]))
                in_view |= np.abs(azimuth) <= fov[radar] / 2
            tally.labels_in_fov += int(in_view.sum())
            tally.labels_with_fov_known += rows.size
        # SAR coverage of labelled cars within 60 m.
        centers_ecef = poses.ego_to_ecef(np.stack([x, y, np.zeros_like(x)], axis=1), stamp) if rows.size else np.zeros((0, 3))
        covered = np.zeros(rows.size, bool)
        for sensor in sar.sensors:
            frame = sar.frame_index(sensor, stamp)
            if frame is not None and rows.size:
                covered |= sar.pixels(sensor, frame, centers_ecef)[1]
        for b in RANGE_BANDS:
            tally.sar_checked[b] += int(np.count_nonzero(bands == b))
            tally.sar_covered[b] += int(np.count_nonzero(covered & (bands == b)))
        # Moving cars' boxes in the ego frame at this frame: truth where known, else the labels.
        car_center, car_length, car_width, car_yaw, car_velocity = (
            np.stack([x, y], axis=1), labels["length"][rows], labels["width"][rows], labels["yaw"][rows],
            np.stack([labels["vx"][rows], labels["vy"][rows]], axis=1),
        )
        if truth is not None:
            t_s = (stamp - truth.start_ns) * 1e-9
            annotatable = annotatable_cars(truth.world, truth.ego, t_s, views)
            labelled_tracks = set(labels["track_id"][rows].tolist())
            tally.annotatable += len(annotatable)
            tally.annotatable_unlabelled += sum(truth.world.cars[i].track_id not in labelled_tracks for i, _ in annotatable)
            rotation, translation = ego_model.enu_T_ego(truth.ego, np.array(t_s))
            moving = [c for c in truth.world.cars if np.hypot(*c.trajectory.velocity_at(np.array(t_s))[:2]) > MIN_SPEED_MPS]
            if moving:
                car_center = np.array([unrotate(rotation, c.trajectory.position_at(np.array(t_s)) - translation)[:2] for c in moving])
                car_velocity = np.array([unrotate(rotation, c.trajectory.velocity_at(np.array(t_s)))[:2] for c in moving])
                car_length = np.array([c.size_m[0] for c in moving])
                car_width = np.array([c.size_m[1] for c in moving])
                ego_yaw = math.atan2(rotation[1, 0], rotation[0, 0])
                car_yaw = np.array([float(c.trajectory.yaw_at(np.array(t_s))) - ego_yaw for c in moving])
            else:
                car_center = np.zeros((0, 2))
                car_velocity = np.zeros((0, 2))
                car_length = car_width = car_yaw = np.zeros(0)
        # CFAR on each radar's latest cube at or before the frame (the loader's rule, so the AP is the
        # example's); points moved into this frame's ego frame.
        frame_points, frame_snr, label_hit = [], [], np.zeros(rows.size, bool)
        for radar in radars:
            k = latest_cube(radar_times[radar], stamp)
            if k is None:
                continue
            cube_ns = int(radar_times[radar][k])
            found = radar_points(np.asarray(cubes[radar][k]), cube_ns, calibration.sensors[radar], poses)
            points = poses.ecef_to_ego(poses.ego_to_ecef(found.points_ego, cube_ns), stamp)
            dt = (cube_ns - stamp) * 1e-9
            on_car = _in_boxes(points[:, :2], car_center + car_velocity * dt, car_length, car_width, car_yaw).any(axis=1) \
                if car_center.shape[0] else np.zeros(points.shape[0], bool)
            if rows.size:
                label_hit |= _in_boxes(points[:, :2], np.stack([x, y], 1) + np.stack([labels["vx"][rows], labels["vy"][rows]], 1) * dt,
                                       labels["length"][rows], labels["width"][rows], labels["yaw"][rows]).any(axis=0)
            # The baselines' own static-scene reading of each point (the SAR frame nearest the cube).
            with np.errstate(divide="ignore"):
                snr_db = 10.0 * np.log10(found.snr)
            ecef_T_cube_ego, test = poses.ecef_T_ego(cube_ns), SarTestParams()
            sar_db = sar_db_at(sar, ecef_T_cube_ego.transform_points(found.points_ego), cube_ns, rd_snr_db=snr_db,
                               max_frame_gap_ns=test.max_frame_gap_ns, shadow_margin_m=test.shadow_margin_m,
                               search_radius_m=test.search_radius_m,
                               radar_ecef=ecef_T_cube_ego.transform_points(ego_T_sensor(calibration.sensors[radar]).translation[None])[0])
            tally.band.extend(_band(np.hypot(points[:, 0], points[:, 1])).tolist())
            tally.on_car.extend(on_car.tolist())
            tally.sar_db.extend(sar_db.tolist())
            tally.doppler_mps.extend(np.abs(found.residual_mps).tolist())
            frame_points.append(points[found.moving])
            frame_snr.append(found.snr[found.moving])
        for b in RANGE_BANDS:
            tally.detected[b] += int(np.count_nonzero(label_hit & (bands == b)))
        fid = frame_id(reader.scene_id, stamp)
        tally.predictions[fid] = cluster_cars(np.concatenate(frame_points) if frame_points else np.zeros((0, 3)),
                                              np.concatenate(frame_snr) if frame_snr else np.zeros(0))
        tally.ground_truth[fid] = [{"x": float(a), "y": float(b)} for a, b in zip(x, y)]


def _share(numerator: int, denominator: int) -> float | None:
    return numerator / denominator if denominator else None


def _auc(on_car: np.ndarray, score: np.ndarray) -> float | None:
    keep = np.isfinite(score)
    labels, values = on_car[keep], score[keep]
    if labels.size == 0 or labels.all() or not labels.any():
        return None
    return float(roc_auc_score(labels, values))


def fidelity_report(
    root: str | os.PathLike, split: str | None = None, *, storage_options: dict | None = None,
    max_frames_per_scene: int | None = None, progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Measure a dataset's fidelity (see the module docstring); returns the ``fidelity.json`` dict.

    Parameters
    ----------
    root : str or path
        Dataset root.
    split : str, optional
        Only this split's scenes (default: every scene).
    max_frames_per_scene : int, optional
        Only the first frames of each scene (quick looks).
    progress : callable, optional
        Called with each scene id before it is measured.

    Raises
    ------
    ZendarError
        For a dataset without any labelled scene with SAR frames in the chosen scenes.
    """
    index = open_dataset(root, storage_options)
    scene_ids = index.scene_ids(split) if split is not None else index.scene_ids()
    truth_of = _simulation_truth(str(root))
    tally = _Tally()
    for scene_id in scene_ids:
        if progress is not None:
            progress(scene_id)
        with index.open_scene(scene_id) as reader:
            _scene(reader, truth_of(scene_id) if truth_of else None, tally, max_frames_per_scene)
    if not tally.frames:
        raise ZendarError(f"{root}: expected labelled scenes with SAR frames{f' in split {split!r}' if split else ''}, found none")
    band = np.array(tally.band, dtype=object)
    on_car = np.array(tally.on_car, bool)
    sar_db = np.array(tally.sar_db, np.float64)
    doppler = np.array(tally.doppler_mps, np.float64)
    detections: dict[str, Any] = {}
    auc_sar: dict[str, float | None] = {}
    auc_doppler: dict[str, float | None] = {}
    for b in (*RANGE_BANDS, ALL_BAND):
        sel = band != "" if b == ALL_BAND else band == b
        detections[b] = {
            "on_moving_cars": int(np.count_nonzero(on_car & sel)),
            "static": int(np.count_nonzero(~on_car & sel)),
            "outside_sar": int(np.count_nonzero(sel & ~np.isfinite(sar_db))),
        }
        # Darker SAR (lower dB) and larger Doppler residuals say "moving": scores increase with that.
        auc_sar[b] = _auc(on_car[sel], -sar_db[sel])
        auc_doppler[b] = _auc(on_car[sel], doppler[sel])
    metrics = evaluate_record({"meta": {"method": "classical_detector (fidelity report)"}, "results": tally.predictions},
                              {"frames": tally.ground_truth})
    n_labels = sum(tally.labels[b] for b in RANGE_BANDS)
    return {
        "root": str(root),
        "split": split,
        "scenes": len(scene_ids),
        "frames": tally.frames,
        "truth": truth_of is not None,
        "bands_m": {b: list(BANDS_M[b]) for b in RANGE_BANDS},
        "labels_per_band": dict(tally.labels),
        "labels_in_radar_fov": {
            "in_view": tally.labels_in_fov, "labels": tally.labels_with_fov_known,
            "share": _share(tally.labels_in_fov, tally.labels_with_fov_known),
        },
        "labels_behind_ego": tally.labels_behind_ego,
        "visible_moving_cars": tally.annotatable if truth_of else None,
        "visible_moving_cars_without_label": tally.annotatable_unlabelled if truth_of else None,
        "sar_coverage_within_60m": {
            **{b: _share(tally.sar_covered[b], tally.sar_checked[b]) for b in RANGE_BANDS},
            ALL_BAND: _share(sum(tally.sar_covered.values()), sum(tally.sar_checked.values())),
        },
        "cfar_detection_rate": {
            **{b: _share(tally.detected[b], tally.sar_checked[b]) for b in RANGE_BANDS},
            ALL_BAND: _share(sum(tally.detected.values()), n_labels),
        },
        "cfar_detections": detections,
        "moving_vs_static_auc": {"sar_mask": auc_sar, "doppler": auc_doppler},
        "end_to_end_ap": dict(metrics.ap),
    }


def format_report(report: dict[str, Any]) -> str:
    """The report as a plain-text table."""

    def pct(value: float | None) -> str:
        return "   -  " if value is None else f"{100 * value:5.1f}%"

    def num(value: float | None) -> str:
        return "  -  " if value is None else f"{value:5.3f}"

    lines = [
        f"fidelity of {report['root']}" + (f" (split {report['split']})" if report["split"] else "")
        + f": {report['scenes']} scenes, {report['frames']} frames" + ("" if report["truth"] else ", no simulation truth"),
        f"labels in a radar's field of view: {pct(report['labels_in_radar_fov']['share'])} "
        f"({report['labels_in_radar_fov']['in_view']} / {report['labels_in_radar_fov']['labels']}); "
        f"behind the ego: {report['labels_behind_ego']}",
    ]
    if report["truth"]:
        lines.append(f"visible moving cars without a label: {report['visible_moving_cars_without_label']} "
                     f"(of {report['visible_moving_cars']} visible)")
    lines.append(f"{'':28s}" + "".join(f"{b:>8s}" for b in (*RANGE_BANDS, ALL_BAND)))
    labels = report["labels_per_band"]
    lines.append(f"{'labels':28s}" + "".join(f"{labels[b]:8d}" for b in RANGE_BANDS)
                 + f"{sum(labels[b] for b in RANGE_BANDS):8d}   (+{labels['beyond']} beyond 60 m)")
    rows = [
        ("SAR coverage of labels", report["sar_coverage_within_60m"], pct),
        ("CFAR detection rate", report["cfar_detection_rate"], pct),
        ("AUC moving/static: SAR mask", report["moving_vs_static_auc"]["sar_mask"], num),
        ("AUC moving/static: Doppler", report["moving_vs_static_auc"]["doppler"], num),
        ("AP end-to-end detector", report["end_to_end_ap"], num),
    ]
    for name, values, fmt in rows:
        lines.append(f"{name:28s}" + "".join(f"{fmt(values.get(b)):>8s}" for b in (*RANGE_BANDS, ALL_BAND)))
    det = report["cfar_detections"]
    lines.append(f"{'CFAR detections on moving cars':28s}" + "".join(f"{det[b]['on_moving_cars']:8d}" for b in (*RANGE_BANDS, ALL_BAND)))
    lines.append(f"{'CFAR detections, static':28s}" + "".join(f"{det[b]['static']:8d}" for b in (*RANGE_BANDS, ALL_BAND)))
    return "\n".join(lines)
