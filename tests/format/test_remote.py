"""Reading a dataset from S3-compatible object storage (a local moto server on 127.0.0.1)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.format.conftest import make_dataset
from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.format import open_dataset
from zendar_dataset.format.ground_truth import ground_truth_frames
from zendar_dataset.format.validate import validate_dataset


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["zarr", "hdf5"])
def test_open_dataset_from_s3(tmp_path, s3_server, backend):
    options = s3_server.storage_options
    local = make_dataset(tmp_path / backend, backend, seed=5)
    url = s3_server.upload(local, f"zendar-{backend}")

    remote = open_dataset(url, storage_options=options)
    reference = open_dataset(local)
    assert remote.splits == reference.splits
    for scene_id in ("s0", "s3"):
        got, want = remote.open_scene(scene_id), reference.open_scene(scene_id)
        assert got.calibration.to_json() == want.calibration.to_json() and got.enu_origin == want.enu_origin
        np.testing.assert_array_equal(got.timestamps("sar/right"), want.timestamps("sar/right"))
        for path in ("radar/left/cube", "sar/right/image", "camera/front/image", "tracklog/attitude_wxyz"):
            assert got.array(path)[1:3].tobytes() == want.array(path)[1:3].tobytes(), path
        assert got.lidar_points("top", 2).tobytes() == want.lidar_points("top", 2).tobytes()
        assert (got.labels() is None) == (scene_id == "s3")
    assert ground_truth_frames(url, "train", storage_options=options) == ground_truth_frames(local, "train")
    assert validate_dataset(url, storage_options=options) == []
    with pytest.raises(ZendarFormatError, match="unknown scene"):
        remote.open_scene("nope")
    with pytest.raises(ZendarFormatError, match="expected dataset.json"):
        open_dataset(url.replace("/root", "/elsewhere"), storage_options=options)
