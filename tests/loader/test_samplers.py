import json

import numpy as np
import pytest
import torch.multiprocessing as mp
from tests.loader.conftest import make_dataset

from zendar_dataset.samplers import SceneDistributedSampler, assign_scenes


class FakeDataset:
    def __init__(self, sizes):
        self.sizes = sizes

    def scene_ranges(self):
        offsets = np.concatenate([[0], np.cumsum(self.sizes)])
        return [(f"s{k}", int(offsets[k]), int(offsets[k + 1])) for k in range(len(self.sizes))]


def test_assignment_is_whole_scenes_balanced_and_epoch_deterministic():
    sizes = [50, 10, 30, 30, 20, 40, 25, 25]
    shards = assign_scenes(sizes, 3, seed=1, epoch=0)
    assert sorted(s for shard in shards for s in shard) == list(range(len(sizes)))
    loads = [sum(sizes[s] for s in shard) for shard in shards]
    # LPT guarantee: the heaviest rank is within one (largest) scene of the mean.
    assert max(loads) - sum(sizes) / 3 <= max(sizes)
    assert max(loads) - min(loads) <= 10
    assert assign_scenes(sizes, 3, seed=1, epoch=0) == shards
    equal = [10] * 8
    epochs = {tuple(map(tuple, assign_scenes(equal, 2, seed=0, epoch=e))) for e in range(6)}
    assert len(epochs) > 1  # equal-sized scenes move between ranks across epochs


def test_sampler_pads_or_drops_to_equal_lengths():
    ds = FakeDataset([5, 3, 4])
    samplers = [SceneDistributedSampler(ds, num_replicas=2, rank=r, seed=3) for r in (0, 1)]
    shards = [set(s.scenes()) for s in samplers]
    assert shards[0].isdisjoint(shards[1]) and shards[0] | shards[1] == {"s0", "s1", "s2"}
    # Scene sizes 5 | 3 + 4: both ranks yield 7 indices; rank holding s0 repeats its own.
    lists = [list(s) for s in samplers]
    assert [len(x) for x in lists] == [7, 7]
    ranges = {sid: (a, b) for sid, a, b in ds.scene_ranges()}
    for sampler, indices in zip(samplers, lists):
        allowed = {i for sid in sampler.scenes() for i in range(*ranges[sid])}
        assert set(indices) == allowed
    dropping = [SceneDistributedSampler(ds, num_replicas=2, rank=r, drop_last=True) for r in (0, 1)]
    assert [len(list(s)) for s in dropping] == [5, 5]


def test_sampler_shuffles_per_epoch_deterministically():
    ds = FakeDataset([20, 20])
    a = SceneDistributedSampler(ds, num_replicas=2, rank=0, seed=5)
    b = SceneDistributedSampler(ds, num_replicas=2, rank=0, seed=5)
    assert list(a) == list(b)
    first = list(a)
    a.set_epoch(1)
    b.set_epoch(1)
    assert list(a) == list(b) and list(a) != first
    ordered = SceneDistributedSampler(ds, num_replicas=2, rank=0, shuffle=False)
    assert list(ordered) == sorted(ordered)


def test_sampler_rejects_bad_arguments():
    with pytest.raises(ValueError, match="cannot be shared among 3 ranks"):
        SceneDistributedSampler(FakeDataset([5, 5]), num_replicas=3, rank=0)
    with pytest.raises(ValueError, match="rank must be"):
        SceneDistributedSampler(FakeDataset([5, 5]), num_replicas=2, rank=2)
    with pytest.raises(ValueError, match="process group"):
        SceneDistributedSampler(FakeDataset([5, 5]))


@pytest.mark.slow
def test_two_gloo_processes_shard_whole_scenes(tmp_path):
    from tests.loader import _workers

    root = make_dataset(tmp_path / "ds", "zarr")
    mp.spawn(
        _workers.sampler_rank,
        args=(2, str(tmp_path / "init"), str(root), str(tmp_path)),
        nprocs=2,
        join=True,
    )
    ranks = [json.loads((tmp_path / f"rank{r}.json").read_text()) for r in (0, 1)]
    assert [r["world"] for r in ranks] == [2, 2]
    for epoch in ("0", "1"):
        views = [r["result"][epoch] for r in ranks]
        assert views[0] == views[1]  # all_gather: both ranks saw the same shards
        per_rank = views[0]
        scenes = [set(v["scenes"]) for v in per_rank]
        assert scenes[0].isdisjoint(scenes[1]) and scenes[0] | scenes[1] == {"alpha", "beta"}
        lengths = [len(v["indices"]) for v in per_rank]
        assert lengths[0] == lengths[1] == 10  # alpha has 10 frames; beta's 6 are padded to 10
