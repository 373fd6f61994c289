"""Range-Doppler masks: segment growth on hand-made maps, the uncertain class of the automatic labels
on simulated point targets, and manual-label masks checked against the simulator's own car boxes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.detection.chain_helpers import T0_NS, parked_poses, radar_calibration, radar_params, sar_frame, sar_frames, simulate_cube
from zendar_dataset.detection import ChainParams
from zendar_baselines.labels.mask_classes import BACKGROUND, MOVING, UNCERTAIN
from zendar_baselines.labels.masks import (
    MaskParams,
    auto_label_mask,
    box_label_mask,
    cfar_peak_label_mask,
    cubes_with_boxes,
    cfar_peaks_on_boxes,
    grow_segments,
    scene_masks,
)
from zendar_dataset.detection import LabelBoxes, cfar_map, cube_power
from zendar_dataset.detection.static_scene import SarTestParams
from zendar_dataset.detection.locate import locate_cells
from zendar_dataset.errors import ZendarError
from zendar_dataset.format.reader import open_dataset
from zendar_dataset.sim import ego as ego_model
from zendar_dataset.sim.generate import synthesize_dataset
from zendar_dataset.sim.labels import MIN_SPEED_MPS
from zendar_dataset.sim.profiles import PROFILES
from zendar_dataset.sim.rotate import unrotate
from zendar_dataset.sim.scene import build_scene

FLOOR_DB = -50.0
SEED = 3


def _map(cells: dict[tuple[int, int], float], shape=(10, 8)) -> np.ndarray:
    power_db = np.full(shape, FLOOR_DB)
    for cell, value in cells.items():
        power_db[cell] = value
    return power_db


def _cells(mask: np.ndarray) -> set[tuple[int, int]]:
    return {(int(r), int(d)) for r, d in zip(*np.nonzero(mask))}


def test_a_segment_is_the_4_connected_blob_within_the_drop_of_its_seed():
    power_db = _map({(2, 2): 30, (2, 3): 25, (3, 2): 22, (3, 3): 21,  # the blob
                     (4, 3): 15,  # connected, but 15 dB below the seed
                     (1, 1): 28,  # touches the blob only by a corner
                     (2, 5): 29})  # a separate peak beyond a gap
    grown = grow_segments(power_db, [2], [2], drop_db=10.0, floor_db=-40.0)
    assert _cells(grown) == {(2, 2), (2, 3), (3, 2), (3, 3)}
    both = grow_segments(power_db, [2, 2], [2, 5], drop_db=10.0, floor_db=-40.0)
    assert _cells(both) == {(2, 2), (2, 3), (3, 2), (3, 3), (2, 5)}


def test_segments_wrap_in_doppler_stop_at_the_window_and_the_floor():
    power_db = _map({(7, 0): 30, (7, 7): 25, (7, 6): 24, (6, 7): 26})  # across the Doppler edge
    assert _cells(grow_segments(power_db, [7], [0], drop_db=10.0, floor_db=-40.0)) == {(7, 0), (7, 7), (7, 6), (6, 7)}
    ridge = _map({(r, 4): 30.0 for r in range(10)})  # a ridge along range
    assert _cells(grow_segments(ridge, [5], [4], drop_db=10.0, half_window=(2, 2))) == {(r, 4) for r in range(3, 8)}
    floor_db = np.full(ridge.shape, -40.0)
    floor_db[6, 4] = 35.0  # a cell under the noise floor cuts the ridge
    assert _cells(grow_segments(ridge, [5], [4], drop_db=10.0, floor_db=floor_db, half_window=(2, 2))) == {(3, 4), (4, 4), (5, 4)}
    with pytest.raises(ZendarError, match="seeds"):
        grow_segments(ridge, [10], [0], drop_db=10.0)


def test_a_cluster_mixing_a_bright_static_point_and_a_moving_one_is_uncertain():
    params = radar_params(n_samples=128, n_chirps=32)
    calibration = radar_calibration(params, 0.0, (0.0, 0.0, 0.0))  # radar frame = ego frame
    bin_mps = params.doppler_bin_mps
    targets = {  # ego xy, radial speed in Doppler bins; bright in SAR?
        "static in the mix": ((15.0, 1.0), 0, True),
        "moving in the mix": ((15.6, 1.8), 3, False),
        "moving alone": ((20.0, -5.0), -4, False),
        "static alone": ((10.0, -6.0), 0, True),
    }
    positions = np.array([(x, y, 0.0) for (x, y), _, _ in targets.values()])
    directions = positions / np.linalg.norm(positions, axis=1, keepdims=True)
    velocities = directions * np.array([bins * bin_mps for _, bins, _ in targets.values()])[:, None]
    # Peaks ~30 dB over the noise: the -32 dB sidelobes stay below it, one CFAR peak per target.
    cube = simulate_cube(params, positions, velocities, np.ones(4), noise=0.3, seed=SEED)
    poses = parked_poses()
    bright = [xy for xy, _, is_bright in targets.values() if is_bright]
    # The static targets' SAR pixels read 60 dB over the median, 20-40 dB above their range-Doppler SNR
    # (the SAR test's value); the movers' points on noise read 10-35 dB below theirs.
    sar = sar_frames(front=sar_frame(poses, (5.0, -10.0), 0.1, (200, 150), bright, 1000.0))
    mask_params = MaskParams(chain=ChainParams(sar=SarTestParams(threshold_db=0.0)))
    mask = auto_label_mask(cube, T0_NS, calibration, poses, sar, mask_params)
    expected = {"static in the mix": UNCERTAIN, "moving in the mix": UNCERTAIN, "moving alone": MOVING, "static alone": BACKGROUND}
    for (name, ((x, y), bins, _)), position in zip(targets.items(), positions):
        cell = (int(round(np.linalg.norm(position) / params.range_bin_m)), cube.shape[1] // 2 + bins)
        assert mask[cell] == expected[name], name
    assert set(np.unique(mask).tolist()) == {BACKGROUND, MOVING, UNCERTAIN}
    half_r, half_d = mask_params.half_window  # each segment stays in its seed's window
    r_moving, d_moving = np.nonzero(mask == MOVING)
    r_seed = int(round(np.linalg.norm(positions[2]) / params.range_bin_m))
    assert np.all(np.abs(r_moving - r_seed) <= half_r) and np.all(np.abs(d_moving - (cube.shape[1] // 2 - 4)) <= half_d)
    assert r_moving.size > 1  # a segment, not a lone cell


@pytest.fixture(scope="module")
def tiny_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("masks") / "tiny"
    synthesize_dataset(root, "tiny", n_scenes=2, seed=SEED, split_ratios=(1, 0, 1), withhold_test_labels=True, progress=False)
    return root


def _truth_boxes(truth, timestamp_ns: int) -> LabelBoxes:
    """The simulator's moving cars at a time, in its true ego frame (independent of labels and poses)."""
    t_s = np.array((timestamp_ns - truth.start_ns) * 1e-9)
    rotation, translation = ego_model.enu_T_ego(truth.ego, t_s)
    ego_yaw = math.atan2(rotation[1, 0], rotation[0, 0])
    cars = [c for c in truth.world.cars if np.hypot(*c.trajectory.velocity_at(t_s)[:2]) > MIN_SPEED_MPS]
    centre = np.array([unrotate(rotation, c.trajectory.position_at(t_s) - translation)[:2] for c in cars]).reshape(-1, 2)
    return LabelBoxes(
        timestamp_ns, centre[:, 0], centre[:, 1], np.array([c.size_m[0] for c in cars]), np.array([c.size_m[1] for c in cars]),
        np.array([float(c.trajectory.yaw_at(t_s)) - ego_yaw for c in cars]), np.zeros(len(cars)), np.zeros(len(cars)),
    )


@pytest.mark.parametrize("manual_targets", ["boxes", "cfar-peaks"])
def test_label_masks_mark_cells_that_map_back_inside_the_simulated_cars(tiny_root, manual_targets):
    index = open_dataset(tiny_root)
    (scene_id,) = index.scene_ids("train")
    truth = build_scene(PROFILES["tiny"], SEED, int(scene_id.split("-")[1]))
    params = MaskParams(manual_targets=manual_targets)
    with index.open_scene(scene_id) as reader:
        poses = reader.ego_poses()
        labels = reader.labels()
        inside, total = 0, 0
        for radar in reader.sensors("radar"):
            timestamps, masks = scene_masks(reader, radar, "labels", params=params, progress=False)
            assert np.array_equal(timestamps, reader.timestamps(f"radar/{radar}"))
            assert masks.dtype == np.uint8 and masks.shape == (timestamps.size, *reader.array(f"radar/{radar}/cube").shape[1:3])
            cubes = reader.array(f"radar/{radar}/cube")
            for k, cube_ns in enumerate(timestamps.tolist()):
                r_idx, d_idx = np.nonzero(masks[k] == MOVING)
                if r_idx.size == 0:
                    continue
                points, _ = locate_cells(np.asarray(cubes[k]), r_idx, d_idx, cube_ns, reader.calibration.sensors[radar], poses)
                cars = _truth_boxes(truth, cube_ns)
                inside += int(cars.contains(points[:, :2], params.box_margin_m).any(axis=1).sum())
                total += r_idx.size
        # The boxes moved from the nearest label frame to a cube's time sit on the simulated cars.
        frame_ns = int(labels["timestamp_ns"][0])
        moved = LabelBoxes.of_frame(labels, frame_ns).moved_to(frame_ns - 60_000_000, poses)
        cars = _truth_boxes(truth, frame_ns - 60_000_000)
        gaps = np.hypot(moved.x[:, None] - cars.x[None], moved.y[:, None] - cars.y[None]).min(axis=1)
        assert gaps.max() < 0.05
    assert total >= 20
    # Grown cells may reach past the car by a few range bins or a DOA error; most land on it.
    assert inside / total >= 0.9, f"{inside} of {total} moving cells inside the simulated cars"


def test_box_targets_hold_the_simulated_cars_returns_and_the_cells_cfar_missed(tiny_root):
    # The simulator's own returns of each labelled car: the CFAR peaks that DOA places inside its box
    # with its radial velocity (the CFAR-gated target's seeds), measured from the simulated cubes.
    index = open_dataset(tiny_root)
    (scene_id,) = index.scene_ids("train")
    params = MaskParams()
    peaks = {"all": 0, "covered": 0, "moving": 0}
    moving_cells = {"boxes": 0, "cfar-peaks": 0}
    with index.open_scene(scene_id) as reader:
        poses, labels = reader.ego_poses(), reader.labels()
        for radar in reader.sensors("radar"):
            calibration = reader.calibration.sensors[radar]
            for cube_ns, cube, boxes in cubes_with_boxes(reader, radar, labels, poses):
                cells = cfar_map(cube_power(cube), params.chain)[0]
                on_car, _near = cfar_peaks_on_boxes(cube, cells, cube_ns, calibration, poses, boxes, params)
                new = box_label_mask(cube, cube_ns, calibration, poses, boxes, params)
                classes = new[cells.range_bin[on_car], cells.doppler_bin[on_car]]
                peaks["all"] += classes.size
                peaks["covered"] += int(np.isin(classes, (MOVING, UNCERTAIN)).sum())
                peaks["moving"] += int((classes == MOVING).sum())
                moving_cells["boxes"] += int((new == MOVING).sum())
                old = cfar_peak_label_mask(cube, cube_ns, calibration, poses, boxes, params)
                moving_cells["cfar-peaks"] += int((old == MOVING).sum())
    assert peaks["all"] >= 20
    assert peaks["covered"] == peaks["all"], peaks
    # The others lie on parts of a car outside the radar's quoted field of view (UNCERTAIN).
    assert peaks["moving"] >= 0.8 * peaks["all"], peaks
    # The car's cells CFAR did not pick count too.
    assert moving_cells["boxes"] > 1.1 * moving_cells["cfar-peaks"], moving_cells


def test_scene_masks_refuse_a_scene_without_labels_an_unknown_kind_or_radar(tiny_root):
    index = open_dataset(tiny_root)
    (scene_id,) = index.scene_ids("test")
    with index.open_scene(scene_id) as reader:
        radar = reader.sensors("radar")[0]
        with pytest.raises(ZendarError, match=scene_id):
            scene_masks(reader, radar, "labels", progress=False)
        with pytest.raises(ZendarError, match="kind"):
            scene_masks(reader, radar, "lidar", progress=False)
        with pytest.raises(ZendarError, match="no radar 'rear'"):
            scene_masks(reader, "rear", "auto", progress=False)
        timestamps, masks = scene_masks(reader, radar, "auto", progress=False)
        assert masks.shape[0] == timestamps.size and set(np.unique(masks).tolist()) <= {BACKGROUND, MOVING, UNCERTAIN}
