"""ZendarDataset over S3-compatible object storage (a local moto server on 127.0.0.1)."""

import numpy as np
import pytest
from tests.loader.conftest import make_dataset
from torch.utils.data import DataLoader

from zendar_dataset import ZendarDataset


@pytest.mark.slow
def test_dataset_from_s3_matches_local(tmp_path, s3_server):
    local = make_dataset(tmp_path / "ds", "zarr")
    url = s3_server.upload(local, "zendar")
    streams = ("radar", "sar", "lidar", "tracklog", "labels")
    remote = ZendarDataset(url, split="train", streams=streams, cube_window=2, storage_options=s3_server.storage_options)
    here = ZendarDataset(local, split="train", streams=streams, cube_window=2)
    assert len(remote) == len(here)
    for index in (0, 4, len(here) - 1):
        got, want = remote[index], here[index]
        assert got["frame_id"] == want["frame_id"] and got["sync"] == want["sync"]
        np.testing.assert_array_equal(got["radar"]["left"]["cube"], want["radar"]["left"]["cube"])
        np.testing.assert_array_equal(got["sar"]["right"]["image"], want["sar"]["right"]["image"])
        np.testing.assert_array_equal(got["lidar"]["top"]["points"], want["lidar"]["top"]["points"])
        np.testing.assert_allclose(got["enu_T_ego"], want["enu_T_ego"])
        assert got["labels"]["track_id"].tolist() == want["labels"]["track_id"].tolist()
    batches = list(DataLoader(remote, batch_size=4, collate_fn=ZendarDataset.collate))
    assert sum(len(b["frame_id"]) for b in batches) == len(here)
