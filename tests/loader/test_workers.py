import numpy as np
import torch
from torch.utils.data import DataLoader

from zendar_dataset import ZendarDataset


def frames_and_sums(loader):
    frames, sums = [], []
    for batch in loader:
        frames.extend(batch["frame_id"])
        sums.extend(batch["radar"]["left"]["cube"].real.sum(dim=(1, 2, 3, 4)).tolist())
        # Variable-length lidar points arrive as lists of tensors.
        assert all(isinstance(p, torch.Tensor) for p in batch["lidar"]["top"]["points"])
    return frames, sums


def expected(ds):
    frames = [ds[k]["frame_id"] for k in range(len(ds))]
    sums = [float(ds[k]["radar"]["left"]["cube"].real.sum()) for k in range(len(ds))]
    return frames, sums


def check_two_workers(root, start_method):
    ds = ZendarDataset(root, split="train", streams=("radar", "lidar", "tracklog", "labels"), cube_window=2)
    # Touch a scene in the parent first: workers must not reuse its open handles.
    ds[0]
    loader = DataLoader(
        ds,
        batch_size=4,
        num_workers=2,
        collate_fn=ZendarDataset.collate,
        multiprocessing_context=start_method,
    )
    frames, sums = frames_and_sums(loader)
    want_frames, want_sums = expected(ds)
    assert frames == want_frames
    np.testing.assert_allclose(sums, want_sums)


def test_dataloader_two_workers_fork(dataset_root):
    check_two_workers(dataset_root, "fork")
