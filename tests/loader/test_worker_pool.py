"""Batches leaving DataLoader workers through the recycled shared-memory pool
(zendar_dataset.shared_batches): bit-identical to the in-process path, bounded,
never blocking."""

import copy
import gc
import pickle
from multiprocessing.reduction import ForkingPickler

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader

from tests.loader._workers import CollateWithPoolStats
from zendar_dataset import ZendarDataset, shared_batches

# Every DataLoader here fails instead of hanging if a worker ever blocks.
TIMEOUT_S = 60
STREAMS = ("radar", "lidar", "tracklog", "labels")


def make_ds(root, **kwargs):
    # Kept unfilled windows: alpha's first frame has no radar window, so batches mix
    # items with and without radar (those cannot use one batch buffer).
    return ZendarDataset(root, split="train", streams=STREAMS, cube_window=2, keep_unfilled_windows=True, **kwargs)


def assert_same(got, want, where="batch"):
    """Exact equality, tensors compared bit for bit and required to be plain tensors."""
    if isinstance(want, torch.Tensor):
        assert type(got) is torch.Tensor, f"{where}: {type(got).__name__}"
        assert got.dtype == want.dtype and got.shape == want.shape, where
        assert torch.equal(got.view(torch.uint8) if got.is_complex() else got,
                           want.view(torch.uint8) if want.is_complex() else want), where
    elif isinstance(want, dict):
        assert isinstance(got, dict) and got.keys() == want.keys(), where
        for key in want:
            assert_same(got[key], want[key], f"{where}[{key!r}]")
    elif isinstance(want, list):
        assert isinstance(got, list) and len(got) == len(want), where
        for k, (g, w) in enumerate(zip(got, want)):
            assert_same(g, w, f"{where}[{k}]")
    elif isinstance(want, np.ndarray):
        np.testing.assert_array_equal(got, want, err_msg=where)
    else:
        assert got == want, where


def reference_batches(ds, batch_size):
    return list(DataLoader(ds, batch_size=batch_size, collate_fn=ds.collate))


def loader(ds, workers, start_method="fork", **kwargs):
    kwargs.setdefault("batch_size", 4)
    return DataLoader(ds, num_workers=workers, multiprocessing_context=start_method, timeout=TIMEOUT_S, **kwargs)


def check_identical(root, workers, start_method):
    ds = make_ds(root)
    want = reference_batches(ds, 4)
    got = list(loader(ds, workers, start_method, collate_fn=CollateWithPoolStats(ds)))
    assert len(got) == len(want)
    for k, ((batch, cube_types, _), expected) in enumerate(zip(got, want)):
        assert_same(batch, expected, f"batch {k}")
        for name, kind in cube_types.items():
            # A whole radar batch travels through a slot; a batch with a missing window
            # is a list of per-item entries (None among them) and takes no slot.
            whole = isinstance(expected["radar"][name], dict)
            assert kind == ("SlotTensor" if whole else None), (k, name, kind)
    assert any(isinstance(b["radar"]["left"], list) for b in want), "the data must include a mixed batch"


@pytest.mark.parametrize("workers", [1, 2])
def test_batches_bit_identical_to_no_workers_fork(dataset_root, workers):
    check_identical(dataset_root, workers, "fork")


@pytest.mark.slow
@pytest.mark.parametrize("workers", [1, 2])
def test_batches_bit_identical_to_no_workers_spawn(hdf5_root, workers):
    check_identical(hdf5_root, workers, "spawn")


def test_abandoned_iterators_with_persistent_workers_then_full_epoch(zarr_root):
    # A pool of 2 slots per worker with 4 batches prefetched per worker: abandoned
    # batches must neither block the workers nor leak into the next epoch.
    ds = make_ds(zarr_root, worker_pool_slots=2)
    want = reference_batches(ds, 2)
    dl = loader(ds, 2, batch_size=2, collate_fn=ds.collate, persistent_workers=True, prefetch_factor=4)
    for taken in (1, 0, 3):
        it = iter(dl)
        for _ in range(taken):
            next(it)
        del it
    for epoch in range(2):
        got = list(dl)
        assert len(got) == len(want), epoch
        for k, (g, w) in enumerate(zip(got, want)):
            assert_same(g, w, f"epoch {epoch} batch {k}")


@pytest.mark.parametrize("workers", [1, 2])
def test_held_batches_are_never_overwritten(zarr_root, workers):
    # Received batches are the workers' slots: holding some while the loader goes on must
    # keep their bytes (the workers take other slots, or torch's path at the bound).
    ds = make_ds(zarr_root, worker_pool_slots=3)
    want = reference_batches(ds, 2)
    for _ in range(2):
        held = list(loader(ds, workers, batch_size=2, collate_fn=ds.collate))
        assert len(held) == len(want)
        for k, (got, expected) in enumerate(zip(held, want)):
            assert_same(got, expected, f"held batch {k}")


def test_pool_growth_is_bounded_and_falls_back(zarr_root):
    # The worker holds its first 3 batches: with 2 slots it must fall back, not wait.
    ds = make_ds(zarr_root, worker_pool_slots=2)
    want = reference_batches(ds, 2)
    got = list(loader(ds, 1, batch_size=2, collate_fn=CollateWithPoolStats(ds, hold=3)))
    for k, ((batch, _, _), expected) in enumerate(zip(got, want)):
        assert_same(batch, expected, f"batch {k}")
    stats = [s for _, _, s in got]
    assert max(s["slots"] for s in stats) == 2
    assert stats[-1]["fallbacks"] > 0
    kinds = [t["left"] for _, t, _ in got]
    assert "SlotTensor" in kinds and "Tensor" in kinds  # pooled, then torch's path


def test_pool_off_and_custom_collate_in_worker(zarr_root):
    ds = make_ds(zarr_root, worker_pool_slots=0)
    want = reference_batches(ds, 4)
    got = list(loader(ds, 1, collate_fn=CollateWithPoolStats(ds)))
    for (batch, cube_types, stats), expected in zip(got, want):
        assert_same(batch, expected)
        assert stats["slots"] == 0 and "SlotTensor" not in cube_types.values()
    with pytest.raises(ValueError, match="worker_pool_slots"):
        make_ds(zarr_root, worker_pool_slots=-1)


class WithDataset:
    """Items that carry their dataset, so a plain function can call its ``collate``."""

    def __init__(self, inner):
        self.inner = inner

    def __len__(self):
        return len(self.inner)

    def __getitems__(self, indices):
        return [{**item, "dataset": self.inner} for item in self.inner.__getitems__(indices)]


def collate_and_scale_right_cubes(items):
    """A user's collate in the worker that post-processes ``ds.collate``'s output."""
    batch = items[0]["dataset"].collate([{k: v for k, v in item.items() if k != "dataset"} for item in items])
    cube = batch["radar"]["right"]["cube"]
    cube.mul_(2)  # in place, on the slot
    batch["radar"]["right"]["halved"] = cube * 0.5  # a new tensor computed from a slot tensor
    return batch


def test_user_collate_modifying_slot_tensors(zarr_root):
    ds = ZendarDataset(zarr_root, split="train", streams=("radar",), cube_window=2)
    want = reference_batches(ds, 4)
    got = list(loader(WithDataset(ds), 1, collate_fn=collate_and_scale_right_cubes))
    assert len(got) == len(want)
    for batch, expected in zip(got, want):
        assert_same(batch["radar"]["right"]["cube"], 2 * expected["radar"]["right"]["cube"])
        assert_same(batch["radar"]["right"]["halved"], expected["radar"]["right"]["cube"])
        assert_same(batch["radar"]["left"]["cube"], expected["radar"]["left"]["cube"])


# -- the pool itself, in this process --------------------------------------------


def test_slot_lifecycle_views_sending_and_return(monkeypatch):
    # This process plays a worker, with a pool of its own for this test.
    pool = shared_batches.WorkerBatchPool()
    monkeypatch.setattr(shared_batches, "_POOL", pool)
    first = pool.buffer((2, 3), np.complex64, max_slots=2)
    first[...] = np.arange(6).reshape(2, 3) * (1 + 1j)
    row = first[1]
    del first
    gc.collect()
    # A view alone keeps the slot leased: a new buffer takes a second slot.
    second = pool.buffer((2, 3), np.complex64, max_slots=2)
    assert pool.stats() == {"slots": 2, "leased": 2, "fallbacks": 0}
    assert pool.buffer((2, 3), np.complex64, max_slots=2) is None
    assert pool.stats()["fallbacks"] == 1
    np.testing.assert_array_equal(row, [3 + 3j, 4 + 4j, 5 + 5j])
    del row
    gc.collect()
    # Released unsent: free at once, and reused rather than grown.
    third = pool.buffer((1, 3), np.complex64, max_slots=2)
    assert third is not None and pool.stats() == {"slots": 2, "leased": 2, "fallbacks": 1}

    second[...] = 7 - 1j
    tensor = pool.tensor([second[0], second[1]])
    assert type(tensor) is shared_batches.SlotTensor
    assert type(tensor + 1) is torch.Tensor
    # Copies made in the worker are ordinary tensors and leave the slot unsent.
    assert type(copy.deepcopy(tensor)) is torch.Tensor
    restored = pickle.loads(pickle.dumps(tensor))
    assert type(restored) is torch.Tensor and torch.equal(restored, torch.full((2, 3), 7 - 1j))
    assert pool.tensor([second[1], second[0]]) is None  # not the rows in order
    assert pool.tensor([second[0]]) is None  # not all rows
    sent = ForkingPickler.dumps(tensor)
    again = pickle.loads(ForkingPickler.dumps(tensor))  # a second send copies the ordinary way
    del tensor, second, third
    gc.collect()
    # Sent and not yet received: the slot stays busy though the worker dropped it.
    held = pool.buffer((2, 3), np.complex64, max_slots=2)  # the slot `third` had
    assert held is not None
    assert pool.buffer((2, 3), np.complex64, max_slots=2) is None
    received = pickle.loads(sent)
    assert type(received) is torch.Tensor and received.dtype == torch.complex64
    assert torch.equal(received, torch.full((2, 3), 7 - 1j))
    assert torch.equal(again, received)
    # The received tensor is the slot: reserved while it or any view of it lives.
    view = received[1].numpy()
    del received
    gc.collect()
    assert pool.buffer((2, 3), np.complex64, max_slots=2) is None
    np.testing.assert_array_equal(view, np.full(3, 7 - 1j, np.complex64))
    del view
    gc.collect()
    assert pool.buffer((2, 3), np.complex64, max_slots=2) is not None


def test_pool_replaces_a_small_free_slot_at_the_bound():
    pool = shared_batches.WorkerBatchPool()
    small = pool.buffer((1, 4), np.float32, max_slots=1)
    del small
    gc.collect()
    big = pool.buffer((1024, 1024), np.float32, max_slots=1)
    assert big is not None and big.shape == (1024, 1024)
    assert pool.stats() == {"slots": 1, "leased": 1, "fallbacks": 0}
    assert pool.slots[0].capacity_bytes >= big.nbytes


def test_received_slot_is_mapped_once_and_reused(monkeypatch):
    # This process plays both sides: the worker's pool and the main process's mappings.
    pool = shared_batches.WorkerBatchPool()
    monkeypatch.setattr(shared_batches, "_POOL", pool)
    monkeypatch.setattr(shared_batches, "_RECEIVED", {})
    maps = []
    real_mmap = shared_batches.mmap.mmap
    # The receiving side maps with explicit flags (the pool's own slots do not).
    monkeypatch.setattr(shared_batches.mmap, "mmap", lambda *a, **k: ("flags" in k and maps.append(a)) or real_mmap(*a, **k))

    def send_and_receive(value):
        rows = pool.buffer((2, 3), np.complex64, max_slots=1)
        rows[...] = value
        sent = ForkingPickler.dumps(pool.tensor([rows[0], rows[1]]))
        del rows
        gc.collect()
        return pickle.loads(sent)

    first = send_and_receive(1 + 2j)
    assert len(maps) == 1 and len(shared_batches._RECEIVED) == 1
    address = first.data_ptr()
    del first
    gc.collect()
    second = send_and_receive(3 - 4j)  # the same slot, freed by the first batch's death
    # The main side reused its mapping: no new mmap, the same address, the new bytes.
    assert len(maps) == 1 and second.data_ptr() == address
    assert torch.equal(second, torch.full((2, 3), 3 - 4j))
    # While the batch lives the slot stays reserved, mapping or not.
    assert pool.buffer((2, 3), np.complex64, max_slots=1) is None
    del second
    gc.collect()
    assert pool.buffer((2, 3), np.complex64, max_slots=1) is not None


def test_received_mappings_of_exited_or_replaced_slots_are_dropped(monkeypatch):
    import subprocess
    import sys

    exited = subprocess.Popen([sys.executable, "-c", "pass"])
    exited.wait()
    mapping = lambda: shared_batches.mmap.mmap(-1, shared_batches.HEADER_BYTES)  # noqa: E731
    received = {
        ("dead", 1): shared_batches._ReceivedSlot(mapping(), exited.pid),
        ("live", 1): shared_batches._ReceivedSlot(mapping(), 1),  # pid 1 lives as long as the machine
        ("live", 2): shared_batches._ReceivedSlot(mapping(), 1),
        ("live", 3): shared_batches._ReceivedSlot(mapping(), 1, in_use=True),
    }
    monkeypatch.setattr(shared_batches, "_RECEIVED", dict(received))
    # A worker (pid 1) that now has 2 slots: its oldest received slot is one it replaced.
    shared_batches._prune_received(1, 2)
    assert list(shared_batches._RECEIVED) == [("live", 2), ("live", 3)]
    # Forgotten while in use, a mapping still hands its slot back when its batch dies.
    slot = received[("live", 3)]
    shared_batches._prune_received(1, 0)
    assert shared_batches._RECEIVED == {}
    slot.mapping[0] = shared_batches.BUSY
    slot.release()
    assert slot.mapping[0] == shared_batches.FREE and not slot.in_use
