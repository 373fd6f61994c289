"""Functions run in spawned processes by the loader tests (importable by name)."""

from __future__ import annotations

import json
import os

import torch.distributed as dist


def sampler_rank(rank: int, world_size: int, init_file: str, root: str, out_dir: str) -> None:
    from zendar_dataset import ZendarDataset
    from zendar_dataset.samplers import SceneDistributedSampler

    dist.init_process_group("gloo", init_method=f"file://{init_file}", rank=rank, world_size=world_size)
    try:
        ds = ZendarDataset(root, split="train", streams=("sar",))
        sampler = SceneDistributedSampler(ds, shuffle=True, seed=7)
        result = {}
        for epoch in (0, 1):
            sampler.set_epoch(epoch)
            indices = list(sampler)
            gathered = [None] * world_size
            dist.all_gather_object(gathered, {"indices": indices, "scenes": sampler.scenes()})
            result[epoch] = gathered
            # Items come from this rank's scenes only.
            frames = {ds[i]["scene_id"] for i in indices}
            assert frames == set(sampler.scenes()), (frames, sampler.scenes())
        with open(os.path.join(out_dir, f"rank{rank}.json"), "w") as handle:
            json.dump({"rank": rank, "world": dist.get_world_size(), "result": result}, handle)
    finally:
        dist.destroy_process_group()


class CollateWithPoolStats:
    """``ds.collate`` in a worker, returned with what the worker saw: the type of each
    radar's batched cube before pickling and the worker's pool statistics.

    ``hold`` keeps the first ``hold`` collated batches alive in the worker, so their
    slots stay leased (forcing the pool to grow, then to fall back)."""

    def __init__(self, dataset, hold: int = 0) -> None:
        self.dataset = dataset
        self.hold = hold
        self.held: list = []

    def __call__(self, items):
        from zendar_dataset import shared_batches

        batch = self.dataset.collate(items)
        cube_types = {name: type(radar["cube"]).__name__ if isinstance(radar, dict) else None
                      for name, radar in batch.get("radar", {}).items()}
        if len(self.held) < self.hold:
            self.held.append(batch)
        return batch, cube_types, shared_batches.worker_pool().stats()
