"""Recordings written as the SDK's writer wrote them (its message definitions, the protobuf runtime),
imported with ``zendar-data import-release``: every converted field comes back exactly, both generations."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.release import fixture as fx
from tests.release.sdk_messages import sdk, write_recording
from zendar_dataset.format import open_dataset
from zendar_dataset.format.validate import validate_dataset
from zendar_dataset.release.assumptions import SPEED_OF_LIGHT_MPS
from zendar_dataset.release.records import gps_seconds_to_ns

SCENE_ID = "2020-02-03_2252_001"
# Unit quaternions whose norm is exactly 1.0 in float64, so normalising them changes no bit.
UNIT_WXYZ = [(1.0, 0.0, 0.0, 0.0), (0.5, -0.5, 0.5, -0.5), (0.0, 0.6, 0.8, 0.0), (0.5, 0.5, 0.5, 0.5)]


def _set_vec(vec, xyz) -> None:
    vec.x, vec.y, vec.z = (float(v) for v in xyz)


def _set_quat(quat, wxyz) -> None:
    quat.w, quat.x, quat.y, quat.z = (float(v) for v in wxyz)


def _point_values(rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    """Per-detection values, float32 as the SDK's ``float`` fields hold them."""
    names = ("range", "azimuth", "elevation", "range_velocity", "magnitude", "snr", "rd_mean_snr", "azimuth_variance")
    return {name: rng.normal(size=n).astype(np.float32) for name in names}


# IMU (forward, right, down) -> (x forward, y left, z up): 180 degrees about x.
FLU_FROM_FRD = np.diag([1.0, -1.0, -1.0])


def _write_release(root, generation: str, flu_attitude: bool = False) -> dict:
    """One scene of every converted stream kind, written with the SDK's ``generation`` definitions.

    ``flu_attitude``: each ``Image.attitude`` rotates x-forward, y-left, z-up vectors into ECEF instead
    of the paper's forward-right-down ones.
    """
    m = sdk(generation)
    rng = np.random.default_rng(11)
    scene = root / "2020-02-03_2252" / "001"
    truth: dict = {"sar": {}, "detections": {}}
    times = np.arange(0, 1.0, 0.1)
    for serial, side in fx.SERIALS.items():
        images, states = [], []
        sar, det = [], []
        for k, t in enumerate(times):
            frame = fx.sar_frame(side, float(t), k)
            p_enu, R_ecef_imu, _ = fx.vehicle(float(t))
            i, j = frame.bright_ij
            data = (fx.magnitude_buffer if generation == "2020" else fx.complex_buffer)(i, j, rng)
            image = m["Image"]()
            top = image if generation == "2020" else image.meta
            top.timestamp = frame.timestamp_s
            _set_quat(top.attitude, fx.wxyz(R_ecef_imu @ FLU_FROM_FRD if flu_attitude else R_ecef_imu))
            _set_vec(top.position, fx.enu_to_ecef(p_enu))
            top.frame_id = k
            if generation == "2021":
                image.meta.serial = serial
            image.performance.fps = 10.0
            _set_vec(image.cartesian.model.origin, frame.origin_ecef)
            _set_vec(image.cartesian.model.di, frame.di_ecef)
            _set_vec(image.cartesian.model.dj, frame.dj_ecef)
            pixels = image.cartesian.data
            pixels.type = pixels.REAL_32U if generation == "2020" else pixels.COMPLEX_32F
            pixels.rows, pixels.cols, pixels.data = fx.ROWS, fx.COLS, data
            images.append(image)
            sar.append((frame, data))

            n = 3 + k % 3
            values = _point_values(rng, n)
            positions = frame.target_ecef + rng.normal(size=(n, 3))
            state = m["TrackerState"]()
            if generation == "2020":
                state.timestamp.common, state.timestamp.sensor, state.frame_id = frame.timestamp_s, 4.5, k
            else:
                state.meta.timestamp, state.meta.frame_id, state.meta.serial = frame.timestamp_s, k, serial
            first, tenth = ("amplitude", "confidence") if generation == "2020" else ("magnitude", "doa_snr")
            for p in range(n):
                point = state.detection.add()
                point.timestamp.common = frame.timestamp_s
                _set_vec(point.position, positions[p])
                for ours, theirs in (("magnitude", first), ("snr", tenth), ("range", "range"), ("azimuth", "azimuth"),
                                     ("elevation", "elevation"), ("range_velocity", "range_velocity"), ("azimuth_variance", "azimuth_variance")):
                    setattr(point, theirs, float(values[ours][p]))
                if generation == "2021":
                    point.rd_mean_snr = float(values["rd_mean_snr"][p])
            states.append(state)
            det.append((frame.timestamp_s, values, positions))
        write_recording(scene / f"{serial}_images.pbs", images)
        write_recording(scene / f"{serial}_points.pbs", states)
        truth["sar"][side], truth["detections"][side] = sar, det

    poses, pose_truth = [], []
    for k, t in enumerate(np.arange(-0.2, 1.2, 0.05)):
        position = m["Position"](timestamp=fx.T0_S + float(t), update_id=k)
        q, p = UNIT_WXYZ[k % len(UNIT_WXYZ)], fx.enu_to_ecef(fx.vehicle(float(t))[0])
        _set_quat(position.attitude, q)
        _set_vec(position.position, p)
        position.quality.satellite_count, position.quality.gps_status, position.quality.ins_status = 11, 3, 2
        poses.append(position)
        pose_truth.append((position.timestamp, p, q))
    write_recording(scene / "vn200.pbs", poses)
    truth["tracklog"] = pose_truth

    sweeps, lidar_truth = [], []
    for k, t in enumerate(times):
        target = truth["sar"]["left"][k][0].target_ecef
        sweep = m["LidarPointsFrame"](timestamp=fx.T0_S + float(t) + 0.001)
        glob = target + np.vstack([np.zeros(3), rng.normal(size=(6, 3))])
        local = rng.normal(size=(7, 3)) * 20
        intensity = rng.integers(0, 256, 7)
        for g, loc, s in zip(glob, local, intensity):
            point = sweep.point_cloud.add(timestamp=sweep.timestamp, intensity=int(s))
            _set_vec(point.position_global, g)
            _set_vec(point.position_local, loc)
        sweeps.append(sweep)
        lidar_truth.append((sweep.timestamp, glob, local, intensity))
    write_recording(scene / "lidar" / "00" / "stream.pbs", sweeps)
    truth["lidar"] = lidar_truth

    # Range-Doppler and camera messages exist only in the 2020 definitions; a 2021 recording uses those.
    m20 = sdk("2020")
    R, D, A = 16, 8, 4
    model = m20["RangeDopplerImageModel"](num_rx=A, wavelength=0.0039)
    model.range_axis_params.start, model.range_axis_params.delta, model.range_axis_params.count = 0.0, 0.176, R
    model.doppler_axis_params.start, model.doppler_axis_params.delta, model.doppler_axis_params.count = -D / 2 * 0.125, 0.125, D
    rx = rng.normal(size=(A, 3)) * 0.01
    for position in rx:
        _set_vec(model.rx_positions.add(), position)
    write_recording(scene / "range_Doppler" / "left_model.pbs", [model])
    cubes = [(rng.normal(size=(R, D, A)) + 1j * rng.normal(size=(R, D, A))).astype("<c8") for _ in range(3)]
    frames = [m20["RangeDopplerFrame"](timestamp=fx.T0_S + 0.05 * k, data=cube.tobytes()) for k, cube in enumerate(cubes)]
    write_recording(scene / "range_Doppler" / "left_rd.pbs", frames)
    truth["rd"] = (model, rx, cubes, [f.timestamp for f in frames])
    index = []
    for k in range(12):
        record = m20["CameraIndexRecord"](frame_index=100 + k)
        record.timestamp.common, record.timestamp.sensor = fx.T0_S + k / 24, 7.0
        index.append(record)
    write_recording(scene / "camera" / "left" / "index.pbs", index)
    truth["camera"] = [(r.timestamp.common, r.frame_index) for r in index]
    return truth


@pytest.fixture(scope="module", params=["2020", "2021"])
def sdk_import(request, tmp_path_factory):
    root = tmp_path_factory.mktemp(f"sdk{request.param}")
    truth = _write_release(root / "release", request.param)
    from zendar_dataset.cli.data import main

    assert main(["import-release", str(root / "release"), str(root / "out")]) == 0
    return request.param, root / "out", truth


def test_sdk_recording_imports_and_validates(sdk_import):
    generation, out, _ = sdk_import
    assert validate_dataset(out) == []
    (scene,) = json.loads((out / "release_import.json").read_text())["scenes"]
    kinds = {s["path"].rsplit("/", 1)[-1]: s["kind"] for s in scene["streams"]}
    assert kinds["1739000J1Q_images.pbs"] == f"Image ({generation})" and kinds["1739000J2R_points.pbs"] == f"TrackerState ({generation})"
    assert not any(s["unknown_fields"] or s["skipped"] for s in scene["streams"] if s["kind"] != "RangeDopplerImageModel (2020)")
    reader = open_dataset(out).open_scene(SCENE_ID)
    assert {"sar/left", "sar/right", "detections/left", "detections/right", "radar/left", "tracklog"} <= set(reader.streams)


def test_sar_fields_round_trip_exactly(sdk_import):
    generation, out, truth = sdk_import
    reader = open_dataset(out).open_scene(SCENE_ID)
    for side, frames in truth["sar"].items():
        times = reader.array(f"sar/{side}/timestamp_ns")[:]
        images = reader.array(f"sar/{side}/image")[:]
        assert times.tolist() == [gps_seconds_to_ns(frame.timestamp_s) for frame, _ in frames]
        for name in ("origin_ecef", "di_ecef", "dj_ecef"):
            np.testing.assert_array_equal(reader.array(f"sar/{side}/{name}")[:], [getattr(frame, name) for frame, _ in frames])
        for m, (_, data) in enumerate(frames):
            if generation == "2020":  # uint32 magnitudes, pixel (i, j) at flat j*rows + i
                expected = np.frombuffer(data, "<u4").reshape(fx.COLS, fx.ROWS).T.astype(np.complex64)
            else:
                expected = np.frombuffer(data, "<c8").reshape(fx.COLS, fx.ROWS).T
            np.testing.assert_array_equal(images[m], expected)


def test_detection_fields_round_trip_exactly(sdk_import):
    generation, out, truth = sdk_import
    reader = open_dataset(out).open_scene(SCENE_ID)
    ours = {"range_m": "range", "azimuth_rad": "azimuth", "elevation_rad": "elevation",
            "range_velocity_mps": "range_velocity", "magnitude": "magnitude", "snr": "snr"}
    for side, frames in truth["detections"].items():
        assert reader.array(f"detections/{side}/timestamp_ns")[:].tolist() == [gps_seconds_to_ns(t) for t, _, _ in frames]
        offsets = reader.array(f"detections/{side}/offsets")[:]
        assert np.diff(offsets).tolist() == [len(p) for _, _, p in frames]
        for column, field in ours.items():
            np.testing.assert_array_equal(reader.array(f"detections/{side}/{column}")[:], np.concatenate([v[field] for _, v, _ in frames]))
        np.testing.assert_array_equal(reader.array(f"detections/{side}/position_ecef")[:], np.concatenate([p for _, _, p in frames]))


def test_tracklog_lidar_cubes_and_camera_round_trip_exactly(sdk_import):
    generation, out, truth = sdk_import
    reader = open_dataset(out).open_scene(SCENE_ID)
    assert reader.array("tracklog/timestamp_ns")[:].tolist() == [gps_seconds_to_ns(t) for t, _, _ in truth["tracklog"]]
    np.testing.assert_array_equal(reader.array("tracklog/position_ecef")[:], [p for _, p, _ in truth["tracklog"]])
    np.testing.assert_array_equal(reader.array("tracklog/attitude_wxyz")[:], [q for _, _, q in truth["tracklog"]])

    (lidar,) = reader.sensors("lidar")
    assert reader.array(f"lidar/{lidar}/timestamp_ns")[:].tolist() == [gps_seconds_to_ns(t) for t, _, _, _ in truth["lidar"]]
    points = reader.array(f"lidar/{lidar}/points")[:]
    expected = np.concatenate([np.column_stack([local, intensity]) for _, _, local, intensity in truth["lidar"]]).astype(np.float32)
    np.testing.assert_array_equal(points, expected)
    np.testing.assert_array_equal(reader.array(f"lidar/{lidar}/position_ecef")[:], np.concatenate([g for _, g, _, _ in truth["lidar"]]))

    model, rx, cubes, times = truth["rd"]
    assert reader.array("radar/left/timestamp_ns")[:].tolist() == [gps_seconds_to_ns(t) for t in times]
    np.testing.assert_array_equal(reader.array("radar/left/cube")[:], np.stack(cubes))  # centred Doppler axis: as written
    radar = reader.calibration.radar("left")
    assert radar.range_bin_m == model.range_axis_params.delta and radar.doppler_bin_mps == model.doppler_axis_params.delta
    assert radar.center_frequency_hz == SPEED_OF_LIGHT_MPS / model.wavelength
    np.testing.assert_array_equal(radar.rx_positions_m, rx[:, [2, 0, 1]])  # release (left, up, forward) -> (forward, left, up)

    (camera,) = [s.split("/")[1] for s in reader.streams if s.startswith("camera_index/")]
    assert reader.array(f"camera_index/{camera}/timestamp_ns")[:].tolist() == [gps_seconds_to_ns(t) for t, _ in truth["camera"]]
    assert reader.array(f"camera_index/{camera}/frame_index")[:].tolist() == [i for _, i in truth["camera"]]
