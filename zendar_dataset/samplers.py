"""Distributed sampling that keeps every scene on one rank.

Sharding by scene (rather than by item, as ``torch.utils.data.DistributedSampler``
does) means a rank opens only its own scene stores and reads each scene's
chunks sequentially, and no frame of a validation scene leaks across ranks.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np
import torch.distributed as dist
from torch.utils.data import Sampler


def assign_scenes(
    scene_sizes: Sequence[int], num_replicas: int, seed: int = 0, epoch: int = 0
) -> list[list[int]]:
    """Split scenes among ranks, balancing item counts.

    Longest-processing-time greedy: scenes in decreasing size (ties broken by a
    random key drawn from ``seed`` and ``epoch``, so equal-sized scenes move between
    ranks from one epoch to the next) each go to the currently lightest rank
    (lowest rank on ties). Every rank computes the same answer without communicating.

    Returns
    -------
    list[list[int]]
        Scene indices per rank.
    """
    rng = np.random.default_rng([seed, epoch])
    tie_break = rng.permutation(len(scene_sizes))
    order = sorted(range(len(scene_sizes)), key=lambda s: (-int(scene_sizes[s]), tie_break[s]))
    loads = [0] * num_replicas
    shards: list[list[int]] = [[] for _ in range(num_replicas)]
    for scene in order:
        rank = min(range(num_replicas), key=lambda r: (loads[r], r))
        shards[rank].append(scene)
        loads[rank] += int(scene_sizes[scene])
    return shards


class SceneDistributedSampler(Sampler[int]):
    """Each rank gets whole scenes, balanced by item count; deterministic per epoch.

    Parameters
    ----------
    dataset
        A :class:`~zendar_dataset.ZendarDataset` (anything with ``scene_ranges()``
        returning ``(scene_id, start, stop)``).
    num_replicas, rank
        Defaults from the initialised process group (``torchrun``).
    shuffle
        Shuffle items within the rank's scenes each epoch (seeded by ``seed`` and the epoch).
    seed
        Shared by all ranks.
    drop_last
        Ranks usually hold different item counts, and DDP needs equal step counts:
        with ``drop_last=False`` shorter ranks repeat some of their own items up to the
        longest rank's count; with ``True`` every rank stops at the shortest count.

    Notes
    -----
    Call :meth:`set_epoch` at the start of every epoch, as with torch's sampler.
    """

    def __init__(
        self,
        dataset,
        num_replicas: int | None = None,
        rank: int | None = None,
        shuffle: bool = True,
        seed: int = 0,
        drop_last: bool = False,
    ) -> None:
        if num_replicas is None or rank is None:
            if not (dist.is_available() and dist.is_initialized()):
                raise ValueError(
                    "num_replicas and rank are needed when no torch.distributed process group is initialised"
                )
            num_replicas = dist.get_world_size() if num_replicas is None else num_replicas
            rank = dist.get_rank() if rank is None else rank
        if num_replicas < 1 or not 0 <= rank < num_replicas:
            raise ValueError(f"rank must be in [0, {num_replicas}), got rank={rank}")
        self.ranges = [(start, stop) for _, start, stop in dataset.scene_ranges()]
        self.scene_ids = [scene_id for scene_id, _, _ in dataset.scene_ranges()]
        nonempty = sum(stop > start for start, stop in self.ranges)
        if nonempty < num_replicas:
            raise ValueError(
                f"{nonempty} scenes with items cannot be shared among {num_replicas} ranks "
                "with whole scenes per rank; use fewer ranks or torch's DistributedSampler"
            )
        self.num_replicas = num_replicas
        self.rank = rank
        self.shuffle = shuffle
        self.seed = seed
        self.drop_last = drop_last
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)

    def _shards(self) -> list[list[int]]:
        sizes = [stop - start for start, stop in self.ranges]
        return assign_scenes(sizes, self.num_replicas, self.seed, self.epoch)

    def _rank_items(self, shard: list[int]) -> np.ndarray:
        items = [np.arange(*self.ranges[s]) for s in sorted(shard)]
        return np.concatenate(items) if items else np.zeros(0, dtype=np.int64)

    def scenes(self) -> list[str]:
        """Scene ids of this rank for the current epoch."""
        return [self.scene_ids[s] for s in sorted(self._shards()[self.rank])]

    def __len__(self) -> int:
        counts = [self._rank_items(shard).size for shard in self._shards()]
        return min(counts) if self.drop_last else max(counts)

    def __iter__(self) -> Iterator[int]:
        items = self._rank_items(self._shards()[self.rank])
        if self.shuffle:
            rng = np.random.default_rng([self.seed, self.epoch, self.rank])
            items = items[rng.permutation(items.size)]
        target = len(self)
        if items.size < target:
            # Repeat this rank's own items (never another rank's scenes).
            items = np.resize(items, target)
        return iter(items[:target].tolist())
