"""``zendar-data fidelity`` on a tiny simulated dataset: exit 0, every key of fidelity.json, all labels
inside a radar's field of view (recomputed here from the calibration), no visible moving car without
a label; and a label moved behind the ego shows up in the report."""

from __future__ import annotations

import json

import numpy as np
import pytest

from zendar_dataset.cli.data import main
from zendar_dataset.fidelity import fidelity_report
from zendar_dataset.format import open_dataset
from zendar_dataset.sim.generate import synthesize_dataset

KEYS = {
    "root", "split", "scenes", "frames", "truth", "bands_m", "labels_per_band", "labels_in_radar_fov", "labels_behind_ego",
    "visible_moving_cars", "visible_moving_cars_without_label", "sar_coverage_within_60m", "cfar_detection_rate",
    "cfar_detections", "moving_vs_static_auc", "end_to_end_ap",
}


@pytest.fixture(scope="module")
def tiny_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("fidelity") / "tiny"
    synthesize_dataset(root, "tiny", n_scenes=2, seed=11, split_ratios=(1, 0, 0), progress=False)
    return root


def _labels_in_view_by_hand(root) -> tuple[int, int]:
    """Labels whose centre lies within half the field of view of a radar's boresight (yaw from the quaternion)."""
    index = open_dataset(root)
    inside = total = 0
    for scene_id in index.scene_ids():
        with index.open_scene(scene_id) as scene:
            labels = scene.labels()
            radars = scene.sensors("radar")
            sensors = {r: scene.calibration.sensors[r] for r in radars}
            for x, y in zip(labels["x"], labels["y"]):
                total += 1
                for r in radars:
                    w, qx, qy, qz = sensors[r].rotation_wxyz
                    boresight = np.arctan2(2 * (w * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
                    dx, dy = x - sensors[r].translation_m[0], y - sensors[r].translation_m[1]
                    azimuth = np.angle(np.exp(1j * (np.arctan2(dy, dx) - boresight)))
                    if abs(np.degrees(azimuth)) <= sensors[r].fov_azimuth_deg / 2:
                        inside += 1
                        break
    return inside, total


def test_the_fidelity_command_reports_every_key_and_labels_all_in_view(tiny_root, tmp_path, capsys):
    out = tmp_path / "report"
    assert main(["fidelity", str(tiny_root), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "labels in a radar's field of view: 100.0%" in printed
    report = json.loads((out / "fidelity.json").read_text())
    assert KEYS <= set(report)
    inside, total = _labels_in_view_by_hand(tiny_root)
    assert total > 0 and inside == total
    assert report["labels_in_radar_fov"] == {"in_view": total, "labels": total, "share": 1.0}
    assert report["labels_behind_ego"] == 0
    assert report["truth"] is True
    assert report["visible_moving_cars_without_label"] == 0
    assert report["visible_moving_cars"] == total
    assert sum(report["labels_per_band"].values()) == total
    for band in ("near", "mid", "far", "all"):
        assert set(report["moving_vs_static_auc"]["sar_mask"]) >= {band}
        assert set(report["end_to_end_ap"]) >= {band}


def test_a_label_moved_behind_the_ego_is_counted_out_of_view(tiny_root, monkeypatch):
    """The reader hands each scene's first label moved to (-8, 0) (behind the ego): the report must see them."""
    from zendar_dataset.format.reader import SceneReader

    original = SceneReader.labels
    moved_scenes = set()

    def moved(self):
        labels = original(self)
        if labels is not None and labels["x"].size:
            labels = dict(labels, x=labels["x"].copy(), y=labels["y"].copy())
            labels["x"][0], labels["y"][0] = -8.0, 0.0
            moved_scenes.add(self.scene_id)
        return labels

    monkeypatch.setattr(SceneReader, "labels", moved)
    report = fidelity_report(tiny_root)
    assert moved_scenes
    assert report["labels_behind_ego"] == len(moved_scenes)
    assert report["labels_in_radar_fov"]["in_view"] == report["labels_in_radar_fov"]["labels"] - len(moved_scenes)


def test_optional_label_fields_are_valid_and_pass_through_to_ground_truth(tiny_root):
    from zendar_dataset.format.ground_truth import ground_truth_frames
    from zendar_dataset.format.validate import validate_dataset

    assert [p for p in validate_dataset(tiny_root) if "labels" in p or "calibration" in p] == []
    cars = [car for frame in ground_truth_frames(tiny_root, "train").values() for car in frame]
    assert cars
    for car in cars:
        assert isinstance(car["num_radar_scatterers"], int) and car["num_radar_scatterers"] >= 3
        assert isinstance(car["num_lidar_points"], int) and car["num_lidar_points"] >= 0


def test_a_field_of_view_out_of_range_is_named_in_the_calibration_error(tiny_root):
    from zendar_dataset.errors import ZendarFormatError
    from zendar_dataset.format.calibration import Calibration

    index = open_dataset(tiny_root)
    with index.open_scene(index.scene_ids()[0]) as scene:
        document = scene.calibration.to_json()
    assert document["sensors"]["front_left"]["fov_azimuth_deg"] == 120.0
    document["sensors"]["front_left"]["fov_azimuth_deg"] = 0.0
    with pytest.raises(ZendarFormatError, match=r"front_left\.fov_azimuth_deg: expected a number in \(0, 360\]"):
        Calibration.from_json(document)
    del document["sensors"]["front_left"]["fov_azimuth_deg"]
    assert Calibration.from_json(document).radar("front_left").fov_azimuth_deg is None


def test_a_shortened_scene_still_has_its_truth_rebuilt_but_an_edited_profile_does_not(tmp_path):
    from zendar_dataset.sim.profiles import get_profile

    root = tmp_path / "short"
    synthesize_dataset(root, get_profile("tiny").with_duration(0.6), n_scenes=1, seed=11, split_ratios=(1, 0, 0),
                       progress=False)
    report = fidelity_report(root)
    assert report["truth"] is True
    assert report["visible_moving_cars_without_label"] == 0
    assert report["visible_moving_cars"] == report["labels_in_radar_fov"]["labels"] > 0
    # Any other change to the recorded profile: this simulator would not draw the same scenes.
    settings = json.loads((root / "simulation.json").read_text())
    settings["profile"]["sar_aperture_m"] = 0.2
    (root / "simulation.json").write_text(json.dumps(settings))
    assert fidelity_report(root)["truth"] is False


def test_the_sar_mask_auc_reads_the_baselines_static_scene_test(tiny_root, monkeypatch):
    """Every SAR value behind the report's SAR-mask AUC is the detection chain's own reading of a CFAR
    point (the SAR frame nearest the cube's time, not the frame's own image)."""
    from zendar_dataset import fidelity
    from zendar_dataset.detection import cfar_cells, frame_cube_points

    read = []

    def recording(*args, **kwargs):
        values = fidelity_sar_db_at(*args, **kwargs)
        read.append(values)
        return values

    fidelity_sar_db_at = fidelity.sar_db_at
    monkeypatch.setattr(fidelity, "sar_db_at", recording)
    fidelity.fidelity_report(tiny_root)
    by_report = np.concatenate(read)

    index = open_dataset(tiny_root)
    by_chain = []
    for scene_id in index.scene_ids():
        with index.open_scene(scene_id) as reader:
            for _, cube_points in frame_cube_points(reader, lambda radar, k, cube: cfar_cells(cube)):
                by_chain.extend(points.sar_db for points in cube_points)
    by_chain = np.concatenate(by_chain)
    assert np.isfinite(by_report).sum() > 100
    assert set(np.round(by_report[np.isfinite(by_report)], 9)) == set(np.round(by_chain[np.isfinite(by_chain)], 9))
