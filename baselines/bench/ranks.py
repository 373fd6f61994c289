"""``zendar-bench`` under torchrun: rank 0 runs the bench, every rank trains each CNN seed with it.

    torchrun --nproc-per-node N -m zendar_baselines [zendar-bench's options]
    torchrun --nnodes M --nproc-per-node N --rdzv-backend c10d --rdzv-endpoint HOST:29400 -m zendar_baselines ...

With ``WORLD_SIZE`` > 1 (torchrun sets it), rank 0 runs every step as one process would — simulation
(on a Dask cluster with ``--scheduler``), automatic labels, masks, chain fits, scoring, every file
written, resume unchanged — except that each CNN seed is trained, its chain fitted and its test
split predicted by all the ranks together: :func:`zendar_baselines.cnn.training.train` wraps the
model in ``DistributedDataParallel`` and gives each rank ``batch_size / WORLD_SIZE`` samples of every
global batch, and the chain fit's and the predictions' loops over scenes give each rank every
``WORLD_SIZE``-th scene (:class:`SceneShard`), their results gathered on every rank in scene order, so
the fit and the predictions are those of one process. The other ranks write nothing: they wait for
rank 0 to hand them a list of seed steps (:func:`hand_out`), do their part of each, and wait again
(:func:`barrier`) while rank 0 scores it with the evaluator and writes its files. gloo on CPUs, nccl
with ``--device cuda`` (each rank on ``cuda:LOCAL_RANK``).

A rank that fails ends the run: torchrun stops the other ranks when one exits with an error. The
ranks wait for rank 0 for up to :data:`WAIT_FOR_RANK_0` (it may be simulating a dataset meanwhile).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import timedelta
from typing import Any

#: How long a rank waits in a collective for the others: the other ranks wait while rank 0 simulates,
#: labels and scores (gloo's default of 30 minutes is shorter than a paper-config step).
WAIT_FOR_RANK_0 = timedelta(hours=48)


@dataclass(frozen=True)
class Ranks:
    """This process's place among torchrun's: ``rank`` of ``world_size`` (0 of 1 without torchrun)."""

    rank: int
    world_size: int

    @property
    def is_main(self) -> bool:
        """Rank 0: the one that runs the steps and writes the files."""
        return self.rank == 0


def current() -> Ranks:
    """The ranks torchrun set in the environment (``RANK``, ``WORLD_SIZE``)."""
    return Ranks(int(os.environ.get("RANK", "0")), int(os.environ.get("WORLD_SIZE", "1")))


def is_main() -> bool:
    """Whether this process writes the run's files (rank 0, or the only process)."""
    return current().is_main


@contextmanager
def process_group(device: str) -> Iterator[Ranks]:
    """The process group of torchrun's ranks for the block (nothing without torchrun): gloo on CPUs,
    nccl on GPUs, each rank on ``cuda:LOCAL_RANK``; destroyed when the block ends."""
    ranks = current()
    if ranks.world_size <= 1:
        yield ranks
        return
    import torch
    import torch.distributed as dist

    if device == "cuda":
        torch.cuda.set_device(int(os.environ.get("LOCAL_RANK", "0")))
    dist.init_process_group(backend="nccl" if device == "cuda" else "gloo", timeout=WAIT_FOR_RANK_0)
    try:
        yield ranks
    finally:
        dist.destroy_process_group()


def hand_out(batch: list[Any] | None) -> list[Any] | None:
    """Rank 0's ``batch`` on every rank (the others pass None); None from rank 0 means the run is over."""
    import torch.distributed as dist

    box = [batch]
    dist.broadcast_object_list(box, src=0)
    return box[0]


def barrier() -> None:
    """Wait until every rank is here."""
    import torch.distributed as dist

    dist.barrier()


@dataclass(frozen=True)
class SceneShard:
    """The scenes one rank of ``world_size`` reads when the ranks share a per-scene loop (a CNN seed's
    chain fit and scoring): every ``world_size``-th scene from its ``rank``; :meth:`gather` gives every
    rank every rank's results. Without torchrun (one rank) it is every scene, and gathering does nothing.
    """

    rank: int
    world_size: int

    @classmethod
    def here(cls) -> SceneShard:
        """This process's share (all scenes without torchrun)."""
        ranks = current()
        return cls(ranks.rank, ranks.world_size)

    def mine(self, scene_ids: list[str]) -> list[str]:
        """This rank's scenes of ``scene_ids`` (in their order)."""
        return list(scene_ids)[self.rank :: self.world_size]

    def gather(self, parts: dict[str, Any]) -> dict[str, Any]:
        """Every rank's ``parts`` (scene id -> result) in one dict, on every rank."""
        if self.world_size <= 1:
            return parts
        import torch.distributed as dist

        gathered: list[dict[str, Any] | None] = [None] * self.world_size
        dist.all_gather_object(gathered, parts)
        return {scene_id: part for rank_parts in gathered for scene_id, part in (rank_parts or {}).items()}


def follow(train: Callable[[Any], None]) -> None:
    """A rank other than 0: ``train(step)`` each seed step rank 0 hands out, together with it, until it
    says the run is over."""
    while (batch := hand_out(None)) is not None:
        for step in batch:
            train(step)
            barrier()  # rank 0 fits the step's chain and scores it meanwhile


__all__ = ["Ranks", "SceneShard", "WAIT_FOR_RANK_0", "barrier", "current", "follow", "hand_out", "is_main",
           "process_group"]
