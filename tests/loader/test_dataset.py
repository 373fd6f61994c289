import numpy as np
import pytest
import torch
from tests.loader.conftest import (
    CAM_H,
    CAM_W,
    ECEF_R_IMU,
    LABELLED,
    MS,
    SAR_H,
    SAR_W,
    A,
    A_M,
    D,
    R,
    imu_position_ecef,
    radar_times,
    sar_times,
)
from pyproj import Transformer
from scipy.spatial.transform import Rotation

from zendar_dataset import ZendarDataset, ZendarFormatError
from zendar_dataset.format.reader import StoredArray
from zendar_dataset.format.schema import LABEL_FIELDS


def test_items_follow_the_timeline(dataset_root):
    ds = ZendarDataset(dataset_root, split="train", cube_window=1)
    assert len(ds) == 10 + 6
    assert [s for s, _, _ in ds.scene_ranges()] == ["alpha", "beta"]
    for k in range(10):
        item = ds[k]
        t = int(sar_times(10)[k])
        assert item["frame_id"] == f"alpha/{t}" and item["timestamp_ns"] == t
        # The latest radar cube at or before t is the one 10 ms earlier: element 2k.
        cube = item["radar"]["left"]["cube"]
        assert cube.shape == (1, R, D, A) and cube.dtype == np.complex64
        assert np.all(cube == 2 * k) and np.all(item["radar"]["right"]["cube"] == 1000 + 2 * k)
        assert item["sync"]["radar/left"] == -10 * MS
        np.testing.assert_array_equal(item["radar"]["left"]["timestamp_ns"], [t - 10 * MS])
        assert item["sar"]["left"]["image"].shape == (SAR_H, SAR_W)
        assert np.all(item["sar"]["left"]["image"] == k) and np.all(item["sar"]["right"]["image"] == k + 1j)
        np.testing.assert_array_equal(item["sar"]["left"]["origin_ecef"], [A_M + k, k, k])
        np.testing.assert_array_equal(item["sar"]["left"]["aperture_ns"], [t - 40 * MS, t + 40 * MS])
        assert item["sync"]["sar/right"] == 0
        # Lidar sweep k is 7 ms after SAR frame k and holds k + 1 points of value k.
        points = item["lidar"]["top"]["points"]
        assert points.shape == (k + 1, 4) and np.all(points == k)
        assert item["sync"]["lidar/top"] == 7 * MS
        # Camera frames at 3 + 40c ms: nearest to 100k ms within 20 ms.
        c = int(np.argmin(np.abs(3 + 40 * np.arange(25) - 100 * k)))
        dt_ms = 3 + 40 * c - 100 * k
        if abs(dt_ms) <= 20:
            assert item["sync"]["camera/front"] == dt_ms * MS
            assert item["camera"]["front"]["image"].shape == (CAM_H, CAM_W, 3)
            assert np.all(item["camera"]["front"]["image"] == c)
        else:
            assert item["sync"]["camera/front"] is None and item["camera"]["front"] is None


def test_labels_per_frame(dataset_root):
    ds = ZendarDataset(dataset_root, split="train", streams=("sar", "labels"))
    dtypes = {spec.name: spec.dtype for spec in LABEL_FIELDS}
    for k in range(10):
        labels = ds[k]["labels"]
        assert set(labels) == set(dtypes)
        n = LABELLED.get(k, 0)
        for name, values in labels.items():
            assert values.shape == (n,) and values.dtype == dtypes[name], name
        if n:
            np.testing.assert_array_equal(labels["track_id"], 100 * k + np.arange(n))
            np.testing.assert_array_equal(labels["timestamp_ns"], [sar_times(10)[k]] * n)
    # Labels are withheld in the test split.
    test = ZendarDataset(dataset_root, split="test", streams=("sar", "labels"))
    assert test[0]["labels"] is None and test[0]["sync"]["labels"] is None
    assert len(ZendarDataset(dataset_root, split="test", streams=("sar", "labels"), require=("labels",))) == 0


def test_poses_at_reference_time(dataset_root):
    ds = ZendarDataset(dataset_root, split="train", streams=("sar", "tracklog"))
    to_enu = Transformer.from_pipeline("+proj=topocentric +ellps=WGS84 +lat_0=0 +lon_0=0 +h_0=0")
    for k in (0, 3, 8):
        item = ds[k]
        t = item["timestamp_ns"]
        imu = imu_position_ecef([t])[0]
        # Ego origin: 1 m ahead of the IMU (north = +z) and 0.5 m below it (-x).
        expected_ecef_T_ego = np.eye(4)
        expected_ecef_T_ego[:3, :3] = [[0, 0, 1], [0, -1, 0], [1, 0, 0]]
        expected_ecef_T_ego[:3, 3] = imu + [-0.5, 0.0, 1.0]
        np.testing.assert_allclose(item["ecef_T_ego"], expected_ecef_T_ego, atol=1e-9)
        assert item["ecef_T_ego"].dtype == np.float64 and item["enu_T_ego"].shape == (4, 4)
        east, north, up = to_enu.transform(*expected_ecef_T_ego[:3, 3])
        expected_enu_T_ego = np.eye(4)
        expected_enu_T_ego[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]  # forward = north, left = west
        expected_enu_T_ego[:3, 3] = [east, north, up]
        np.testing.assert_allclose(item["enu_T_ego"], expected_enu_T_ego, atol=1e-6)
        np.testing.assert_allclose(item["tracklog"]["position_ecef"], imu, atol=1e-9)
        np.testing.assert_allclose(
            np.abs(item["tracklog"]["attitude_wxyz"]), [np.sqrt(0.5), 0, np.sqrt(0.5), 0], atol=1e-12
        )
        # The attitude read back is the IMU -> ECEF rotation written; the ego's rotation adds the
        # IMU mount (forward, right, down: a half turn about x), so the two differ by that mount.
        read_rotation = Rotation.from_quat(item["tracklog"]["attitude_wxyz"], scalar_first=True).as_matrix()
        np.testing.assert_allclose(read_rotation, ECEF_R_IMU, atol=1e-12)
        np.testing.assert_allclose(item["ecef_T_ego"][:3, :3], ECEF_R_IMU @ np.diag([1.0, -1.0, -1.0]), atol=1e-9)
        poses = ds.ego_poses(item["scene_id"])
        np.testing.assert_allclose(poses.ecef_T_ego(t).as_matrix(), expected_ecef_T_ego, atol=1e-9)
        np.testing.assert_allclose(poses.enu_T_ego(t).as_matrix(), expected_enu_T_ego, atol=1e-6)
    with pytest.raises(ZendarFormatError, match="not in split"):
        ds.ego_poses("no-such-scene")
    # The tracklog ends at 850 ms: the frame at 900 ms has no pose (never extrapolated).
    last = ds[9]
    assert last["ecef_T_ego"] is None and last["sync"]["tracklog"] is None
    required = ZendarDataset(dataset_root, split="train", streams=("sar", "tracklog"), require=("tracklog",))
    assert len(required) == 15
    report = required.sync_report().set_index(["scene_id", "stream"])
    assert report.loc[("alpha", "tracklog"), "dropped"] == 1


def test_cube_window_and_drop_count(dataset_root):
    ds = ZendarDataset(dataset_root, split="train", streams=("radar",), cube_window=3)
    # Frame 0 (0 ms) has one cube at or before it (-10 ms): its window of 3 cannot be filled.
    assert len(ds) == 9 + 5
    item = ds[0]
    assert item["timestamp_ns"] == int(sar_times(10)[1])
    cube = item["radar"]["left"]["cube"]
    assert cube.shape == (3, R, D, A)
    np.testing.assert_array_equal(cube[:, 0, 0, 0].real, [0, 1, 2])
    np.testing.assert_array_equal(item["radar"]["left"]["timestamp_ns"], radar_times(10)[0:3])
    report = ds.sync_report()
    alpha_left = report[(report.scene_id == "alpha") & (report.stream == "radar/left")].iloc[0]
    assert alpha_left["dropped"] == 1 and alpha_left["reference_frames"] == 10 and alpha_left["items"] == 9
    kept = ZendarDataset(dataset_root, split="train", streams=("radar",), cube_window=3, keep_unfilled_windows=True)
    assert len(kept) == 16 and kept[0]["radar"]["left"] is None and kept[0]["sync"]["radar/left"] is None


def test_reference_choices_and_tolerances(dataset_root):
    ds = ZendarDataset(dataset_root, split="train", streams=("sar", "labels"), reference="sar/right")
    assert ds[0]["reference"] == "sar/right" and len(ds) == 16
    # Camera reference: labels come from the nearest SAR frame within its tolerance (50 ms).
    cam = ZendarDataset(dataset_root, split="train", streams=("camera", "sar", "labels"), reference="camera")
    item = cam[2]  # camera frame at 83 ms: nearest SAR frame is 100 ms (+17 ms)
    assert item["timestamp_ns"] == 1_300_000_000_000_000_000 + 83 * MS
    assert item["sync"]["labels"] == 17 * MS and item["label_timestamp_ns"] == int(sar_times(10)[1])
    assert len(item["labels"]["x"]) == LABELLED[1]
    # A tight tolerance leaves the camera out of most frames; require drops them.
    tight = ZendarDataset(dataset_root, split="train", streams=("sar", "camera"), tolerance_ms={"camera": 3.0})
    present = [tight[k]["sync"]["camera/front"] for k in range(10)]
    assert all(p is None or abs(p) <= 3 * MS for p in present)
    assert present[0] == 3 * MS  # exactly at the tolerance: matched
    strict = ZendarDataset(dataset_root, split="train", streams=("sar", "camera"), tolerance_ms=3.0, require=("camera/front",))
    assert 0 < len(strict) < len(tight)


def test_collate_batches(dataset_root):
    ds = ZendarDataset(dataset_root, split="train", cube_window=2)
    batch = ZendarDataset.collate([ds[1], ds[2], ds[3]])
    assert batch["radar"]["left"]["cube"].shape == (3, 2, R, D, A)
    assert batch["radar"]["left"]["cube"].dtype == torch.complex64
    assert batch["timestamp_ns"].dtype == torch.int64 and batch["timestamp_ns"].shape == (3,)
    assert batch["sar"]["left"]["image"].shape == (3, SAR_H, SAR_W)
    assert batch["ecef_T_ego"].shape == (3, 4, 4) and batch["ecef_T_ego"].dtype == torch.float64
    assert isinstance(batch["lidar"]["top"]["points"], list)
    assert [p.shape[0] for p in batch["lidar"]["top"]["points"]] == [3, 4, 5]
    assert isinstance(batch["labels"]["x"], list) and [len(x) for x in batch["labels"]["x"]] == [0, 0, 1]
    assert batch["frame_id"] == [ds[k]["frame_id"] for k in (1, 2, 3)]
    assert batch["sync"]["radar/left"] == [-10 * MS] * 3
    # Items whose camera is missing keep a list with None in its place.
    tight = ZendarDataset(dataset_root, split="train", streams=("camera",), reference="sar", tolerance_ms=3.0)
    mixed = ZendarDataset.collate([tight[0], tight[1]])
    assert isinstance(mixed["camera"]["front"], list) and mixed["camera"]["front"][1] is None
    assert mixed["camera"]["front"][0]["image"].shape == (CAM_H, CAM_W, 3)


def test_transforms_and_repr(dataset_root):
    ds = ZendarDataset(dataset_root, split="train", streams=("sar",), transforms=lambda item: item["frame_id"])
    assert ds[0] == f"alpha/{sar_times(10)[0]}"
    text = repr(ds)
    assert str(dataset_root) in text and "split='train'" in text and "size=16" in text and "['sar']" in text
    assert ds[-1] == f"beta/{sar_times(6)[5]}"
    with pytest.raises(IndexError):
        ds[16]


def test_construction_reads_only_timestamps_and_items_read_one_slice(zarr_root, monkeypatch):
    reads = []
    original = StoredArray.__getitem__

    def counting(self, key):
        reads.append((self.path, key))
        return original(self, key)

    monkeypatch.setattr(StoredArray, "__getitem__", counting)
    ds = ZendarDataset(zarr_root, split="train", cube_window=2)
    assert reads and all(path.endswith("timestamp_ns") for path, _ in reads)
    reads.clear()
    ds[4]
    cube_reads = [(p, k) for p, k in reads if p.endswith("/cube")]
    assert sorted(p for p, _ in cube_reads) == ["radar/left/cube", "radar/right/cube"]
    assert all(isinstance(k, slice) and k.stop - k.start == 2 for _, k in cube_reads)
    assert sum(p.endswith("/image") for p, _ in reads) == 3  # two SAR images and one camera image


def test_construction_survives_deleted_cube_chunks(tmp_path):
    # Bulk chunks are never touched at construction: delete them all and build the index.
    import shutil

    from tests.loader.conftest import make_dataset

    root = make_dataset(tmp_path / "ds", "zarr")
    for scene in ("alpha", "beta"):
        shutil.rmtree(root / "scenes" / f"{scene}.zarr" / "radar" / "left" / "cube" / "c")
        shutil.rmtree(root / "scenes" / f"{scene}.zarr" / "sar" / "left" / "image" / "c")
    ds = ZendarDataset(root, split="train", cube_window=2)
    assert len(ds) == 9 + 5


def test_bad_root_split_scene_and_arguments(dataset_root, tmp_path):
    with pytest.raises(ZendarFormatError, match="dataset.json"):
        ZendarDataset(tmp_path / "nowhere")
    with pytest.raises(ZendarFormatError, match="unknown split 'tain'"):
        ZendarDataset(dataset_root, split="tain")
    ds = ZendarDataset(dataset_root, split="train", streams=("sar",))
    with pytest.raises(ZendarFormatError, match="scene 'gamma' is not in split 'train'"):
        ds.sync_table("gamma")
    with pytest.raises(ValueError, match="'radr' is not a stream"):
        ZendarDataset(dataset_root, streams=("radr",))
    with pytest.raises(ZendarFormatError, match="sensors are"):
        ZendarDataset(dataset_root, streams=("camera/rear",))
    with pytest.raises(ZendarFormatError, match=r"reference 'sar/middle'"):
        ZendarDataset(dataset_root, streams=("sar",), reference="sar/middle")
    with pytest.raises(ValueError, match="require names"):
        ZendarDataset(dataset_root, streams=("sar",), require=("camera",))
    with pytest.raises(ValueError, match="tolerance_ms names"):
        ZendarDataset(dataset_root, streams=("sar", "camera"), tolerance_ms={"lidar": 5.0})
    with pytest.raises(ValueError, match="cube_window"):
        ZendarDataset(dataset_root, streams=("radar",), cube_window=0)


def test_batched_reads_match_items_and_collate_without_copy(dataset_root):
    ds = ZendarDataset(dataset_root, split="train", streams=("radar", "labels"), cube_window=2)
    indices = [0, 5, 9, 12]  # across both scenes
    items = ds.__getitems__(indices)
    for index, item in zip(indices, items):
        single = ds[index]
        assert item["frame_id"] == single["frame_id"]
        np.testing.assert_array_equal(item["radar"]["left"]["cube"], single["radar"]["left"]["cube"])
        np.testing.assert_array_equal(item["radar"]["right"]["timestamp_ns"], single["radar"]["right"]["timestamp_ns"])
    batch = ZendarDataset.collate(items)
    cube = batch["radar"]["left"]["cube"]
    assert cube.shape == (4, 2, R, D, A)
    # The batch tensor is the buffer the items were read into.
    assert cube.data_ptr() == items[0]["radar"]["left"]["cube"].__array_interface__["data"][0]
    # A transform that replaces an array falls back to stacking a copy.
    items[1]["radar"]["left"]["cube"] = items[1]["radar"]["left"]["cube"] * 2
    restacked = ZendarDataset.collate(items)["radar"]["left"]["cube"]
    np.testing.assert_array_equal(restacked[1].numpy(), 2 * ds[5]["radar"]["left"]["cube"])


def test_truncated_cube_chunk_raises_format_error(tmp_path):
    from tests.loader.conftest import make_dataset

    root = make_dataset(tmp_path / "ds", "zarr")
    chunk = root / "scenes" / "alpha.zarr" / "radar" / "left" / "cube" / "c" / "4" / "0" / "0" / "0"  # frame 2 (200 ms) reads cube 4 (190 ms)
    chunk.write_bytes(chunk.read_bytes()[:100])
    ds = ZendarDataset(root, split="train", streams=("radar",))
    with pytest.raises(ZendarFormatError, match=r"alpha: radar/left/cube.*truncated"):
        ds.__getitems__([2, 1])
    with pytest.raises(ZendarFormatError, match=r"alpha: radar/left/cube"):
        ds[2]
