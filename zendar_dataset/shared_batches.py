"""Recycled shared memory for batches leaving DataLoader workers.

A worker that returns a *fresh* shared-memory tensor per batch is limited by the
page faults of that fresh memory (torch allocates a new segment per batch), about
1 GB/s per worker; copying each received batch into fresh memory in the main process
costs about as much again. Here each worker keeps a small pool of slots, each an
anonymous ``memfd`` mapped once, whose pages are faulted once and reused batch after
batch, and the main process hands out the slot itself: nothing is copied, and nothing
is left behind in ``/dev/shm`` (nor limited by its size) if a worker dies. The main
process too maps each slot once and keeps the mapping for the slot's next batches
(dropped when the worker exits or replaces the slot).

Life of a slot::

    worker                                   main process
    ------                                   ------------
    lease: flag = 1, read cubes into it
    collate: SlotTensor over the slot
    pickle: (fd, shape, dtype) -- queue -->  unpickle: map the slot (first time only),
                                             return an ordinary tensor over the mapping
                                             ... the user works with the batch ...
                                             last view of it dies: flag = 0
    lease again once flag == 0 and no
    array of the worker still views it

The worker writes into a slot only while its flag says it is free, and the flag is
cleared only when no tensor, view or numpy array of the main process refers to the
received batch any more (CPython's reference counting releases it deterministically),
so a batch the user holds is never overwritten. A worker never waits for a slot: when
all are busy (batches prefetched or held by the user, or dropped with an abandoned
iterator) the pool grows up to its bound, then the batch takes torch's ordinary path.
"""

from __future__ import annotations

import mmap
import os
import weakref
from dataclasses import dataclass
from multiprocessing.reduction import DupFd, ForkingPickler
from typing import Any

import numpy as np
import torch
from torch.multiprocessing.reductions import reduce_tensor

# The flag lives in the first byte; data starts one page in, so it is page aligned.
HEADER_BYTES = mmap.PAGESIZE
FREE, BUSY = 0, 1
# memfd is Linux's; elsewhere every batch takes torch's ordinary path.
SUPPORTED = hasattr(os, "memfd_create")
MAP_POPULATE = getattr(mmap, "MAP_POPULATE", 0)


@dataclass(eq=False)
class _Slot:
    """One shared-memory segment: ``fd`` (memfd), ``capacity_bytes`` of data after the header."""

    fd: int
    capacity_bytes: int
    mapping: mmap.mmap
    # The worker's array over the slot while any view of it is alive (weak: its death frees the slot).
    array: weakref.ref | None = None
    sent: bool = False

    @property
    def leased(self) -> bool:
        return self.array is not None

    def is_free(self) -> bool:
        return not self.leased and self.mapping[0] == FREE

    def close(self) -> None:
        self.mapping.close()
        os.close(self.fd)


class SlotTensor(torch.Tensor):
    """A batch tensor over a pool slot, inside a worker. Pickled for the DataLoader's
    queue it sends the slot's descriptor, not its bytes; operations on it give plain
    tensors (torch function dispatch is disabled for the subclass)."""

    __torch_function__ = torch._C._disabled_torch_function_impl

    def __deepcopy__(self, memo: dict) -> torch.Tensor:
        copied = memo[id(self)] = self.as_subclass(torch.Tensor).clone()
        return copied

    def __reduce_ex__(self, protocol: int) -> Any:
        # Standard pickling (torch.save, pickle.dumps) stores a plain tensor's bytes.
        return self.as_subclass(torch.Tensor).__reduce_ex__(protocol)


class WorkerBatchPool:
    """The slots of one worker process, created on demand up to ``max_slots``."""

    def __init__(self) -> None:
        self.slots: list[_Slot] = []
        self.leased_by_address: dict[int, _Slot] = {}
        self.fallbacks = 0
        self.pid = os.getpid()

    def buffer(self, shape: tuple[int, ...], dtype: np.dtype, max_slots: int) -> np.ndarray | None:
        """An uninitialised C-contiguous array in a free slot, or None when the pool is
        at ``max_slots`` and none is free and large enough (the caller falls back)."""
        dtype = np.dtype(dtype)
        nbytes = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
        slot = self._take(nbytes, max_slots) if SUPPORTED else None
        if slot is None:
            self.fallbacks += 1
            return None
        slot.mapping[0] = BUSY
        slot.sent = False
        # Built in one step over the mapping: every view of it (numpy collapses view
        # chains to the first array over foreign memory) then keeps this very array alive.
        array = np.ndarray(shape, dtype=dtype, buffer=slot.mapping, offset=HEADER_BYTES)
        address = array.__array_interface__["data"][0]
        slot.array = weakref.ref(array)
        self.leased_by_address[address] = slot
        weakref.finalize(array, self._release, slot, address)
        return array

    def _take(self, nbytes: int, max_slots: int) -> _Slot | None:
        free = [s for s in self.slots if s.is_free()]
        fitting = [s for s in free if s.capacity_bytes >= nbytes]
        if fitting:
            return min(fitting, key=lambda s: s.capacity_bytes)
        if len(self.slots) >= max_slots:
            if not free:
                return None
            # At the bound: replace a free slot too small for this batch.
            smallest = min(free, key=lambda s: s.capacity_bytes)
            self.slots.remove(smallest)
            smallest.close()
        capacity = -(-nbytes // mmap.PAGESIZE) * mmap.PAGESIZE
        fd = os.memfd_create("zendar-batch", os.MFD_CLOEXEC)
        try:
            os.ftruncate(fd, HEADER_BYTES + capacity)
            mapping = mmap.mmap(fd, HEADER_BYTES + capacity)
        except BaseException:
            os.close(fd)
            raise
        slot = _Slot(fd, capacity, mapping)
        self.slots.append(slot)
        return slot

    def _release(self, slot: _Slot, address: int) -> None:
        """The worker's last view of the slot died: unsent, the slot is free at once;
        sent, the main process frees it once it has copied the data."""
        slot.array = None
        self.leased_by_address.pop(address, None)
        if not slot.sent and not slot.mapping.closed:
            slot.mapping[0] = FREE

    def leased_array(self, address: int) -> tuple[_Slot, np.ndarray] | tuple[None, None]:
        """The slot and the worker's array over it, for the data address of a leased slot."""
        slot = self.leased_by_address.get(address)
        array = slot.array() if slot is not None and slot.array is not None else None
        return (slot, array) if array is not None else (None, None)

    def tensor(self, rows: list[Any]) -> SlotTensor | None:
        """The slot tensor when ``rows`` are exactly the rows of one leased array, in order."""
        first = rows[0]
        if not isinstance(first, np.ndarray):
            return None
        _, array = self.leased_array(first.__array_interface__["data"][0])
        if array is None or array.shape[0] != len(rows):
            return None
        start = array.__array_interface__["data"][0]
        for b, row in enumerate(rows):
            if not (isinstance(row, np.ndarray) and row.shape == array.shape[1:] and row.dtype == array.dtype
                    and row.__array_interface__["data"][0] == start + b * array.strides[0]):
                return None
        return torch.from_numpy(array).as_subclass(SlotTensor)

    def stats(self) -> dict[str, int]:
        """``slots`` (created), ``leased`` and ``fallbacks`` (batches that took torch's path)."""
        return {"slots": len(self.slots), "leased": sum(s.leased for s in self.slots), "fallbacks": self.fallbacks}


_POOL: WorkerBatchPool | None = None


def worker_pool() -> WorkerBatchPool:
    """This process's pool (a forked child starts its own: slots are never shared)."""
    global _POOL
    if _POOL is None or _POOL.pid != os.getpid():
        _POOL = WorkerBatchPool()
    return _POOL


def slot_tensor(rows: list[Any]) -> SlotTensor | None:
    """The slot tensor behind ``rows`` (see :meth:`WorkerBatchPool.tensor`); None outside
    a process that leased slots."""
    if _POOL is None or _POOL.pid != os.getpid():
        return None
    return _POOL.tensor(rows)


def _reduce_slot_tensor(tensor: SlotTensor) -> tuple:
    plain = tensor.as_subclass(torch.Tensor)
    nbytes = plain.numel() * plain.element_size()
    # Found by address rather than carried on the tensor, so that copies of it
    # (deepcopy, standard pickling) stay ordinary tensors.
    slot, array = (None, None) if _POOL is None or _POOL.pid != os.getpid() else _POOL.leased_array(plain.data_ptr())
    if slot is None:
        return reduce_tensor(plain)
    if slot.sent or not plain.is_contiguous() or nbytes > array.nbytes:
        # A slot is sent once: a second send of it copies, the ordinary way.
        return reduce_tensor(plain.clone())
    slot.sent = True
    dtype = str(plain.dtype).removeprefix("torch.")
    return _rebuild_from_slot, (DupFd(slot.fd), _POOL.pid, len(_POOL.slots), nbytes, tuple(plain.shape), dtype)


@dataclass(eq=False)
class _ReceivedSlot:
    """The main process's mapping of one worker slot, kept from batch to batch.

    Mapping a 32 MiB batch of shared pages and unmapping it again costs more than
    copying it (9 ms against 6 ms, best of 30, on the 2-core reference machine), and
    the main process paid that for every batch while the workers competed with it for
    the same cores; mapped once, a slot's pages stay mapped. ``in_use`` while an array
    of a received batch views the mapping.
    """

    mapping: mmap.mmap
    pid: int
    in_use: bool = False

    def release(self) -> None:
        """The last array over the batch died: hand the slot back to its worker."""
        # Cleared before the flag: once the flag is free the worker may send the slot again.
        self.in_use = False
        if not self.mapping.closed:
            self.mapping[0] = FREE


# (st_dev, st_ino) of a slot's memfd -> its mapping here, in receipt order (oldest first).
_RECEIVED: dict[tuple[int, int], _ReceivedSlot] = {}
_RECEIVED_PID = os.getpid()


def _prune_received(pid: int, worker_slots: int) -> None:
    """Forget mappings no worker can send again: those of exited workers, and beyond the
    ``worker_slots`` a live worker has, its least recently received ones (slots it replaced).
    A forgotten mapping in use lives on until its batch dies."""
    alive: dict[int, bool] = {}
    for key, slot in list(_RECEIVED.items()):
        if slot.pid not in alive:
            try:
                os.kill(slot.pid, 0)
                alive[slot.pid] = True
            except ProcessLookupError:
                alive[slot.pid] = False
            except PermissionError:
                alive[slot.pid] = True
        if not alive[slot.pid]:
            del _RECEIVED[key]
    from_worker = [key for key, slot in _RECEIVED.items() if slot.pid == pid]
    for key in from_worker[: max(0, len(from_worker) - worker_slots)]:
        del _RECEIVED[key]


def _rebuild_from_slot(dup_fd: Any, pid: int, worker_slots: int, nbytes: int, shape: tuple[int, ...],
                       dtype: str) -> torch.Tensor:
    """In the receiving process: an ordinary tensor over the slot, which stays reserved
    for this tensor (and its views) until they are all gone."""
    global _RECEIVED_PID
    if _RECEIVED_PID != os.getpid():
        # A forked child does not reuse its parent's mappings (its own copies die with the dict).
        _RECEIVED.clear()
        _RECEIVED_PID = os.getpid()
    fd = dup_fd.detach()
    try:
        stat = os.fstat(fd)
        key = (stat.st_dev, stat.st_ino)
        slot = _RECEIVED.pop(key, None)
        if slot is None or slot.in_use or len(slot.mapping) < HEADER_BYTES + nbytes:
            _prune_received(pid, worker_slots - 1)
            # Populated in one call: no page fault per 64 KiB while the batch is read.
            slot = _ReceivedSlot(mmap.mmap(fd, stat.st_size, flags=mmap.MAP_SHARED | MAP_POPULATE), pid)
    finally:
        os.close(fd)  # the mapping keeps the memory
    _RECEIVED[key] = slot  # now the most recently received
    slot.in_use = True
    data = np.frombuffer(slot.mapping, dtype=np.uint8, count=nbytes, offset=HEADER_BYTES)
    weakref.finalize(data, slot.release)
    return torch.from_numpy(data).view(getattr(torch, dtype)).reshape(shape)


ForkingPickler.register(SlotTensor, _reduce_slot_tensor)
