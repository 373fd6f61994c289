"""Claim: streaming radar cubes through ZendarDataset + DataLoader reaches >= 80 % of the
throughput of reading the same bytes raw, from a warm page cache.

For each backend (zarr, HDF5) a scene of N paper-sized cubes ([512, 256, 4]
complex64, 4 MiB) is written once. Compared in the same run, for 0, 1 and 2 workers
(persistent, fork, batch 8, prefetch 4):

* raw (the target's reference): every cube's chunk bytes read straight into a
  preallocated numpy batch in this process (zarr: the chunk file; HDF5: the chunk's
  byte range, located with h5py's chunk index) -- the ceiling of any reader;
* ``ZendarDataset`` + ``ZendarDataset.collate`` (the package);
* what users write today: a torch ``Dataset`` whose ``__getitem__`` opens the
  store (``zarr.open_array`` / ``h5py.File``) and reads one cube, with torch's default
  collate; and the better version of it that keeps the handle open per worker;
* torch's own worker-to-main transfer with the items already in memory (no I/O),
  the ceiling of the default-collate path.

For each worker count, raw and every loader take turns pass by pass (``--repeats``
rounds after one untimed warm-up pass), so that all see the same machine load; the
table gives min / median / max of MB/s and the median ratio to raw. Threads: one
reading thread per process everywhere (numpy/h5py/zarr reads are not threaded here).

Run: python benchmarks/bench_loader.py [--frames 96] [--repeats 7] [--backend zarr hdf5]
"""

from __future__ import annotations

import argparse
import pathlib
import tempfile

import h5py
import numpy as np
import torch
import zarr
from harness import Spread, interleaved, print_environment, print_load_after
from torch.utils.data import DataLoader, Dataset

from zendar_dataset import ZendarDataset
from zendar_dataset.format import DatasetWriter

R, D, A = 512, 256, 4
FRAME_BYTES = R * D * A * 8
T0_NS = 1_300_000_000_000_000_000
CALIBRATION = {
    "sensors": {
        "left": {
            "rotation_wxyz": [1.0, 0.0, 0.0, 0.0],
            "translation_m": [0.0, 0.0, 0.5],
            "center_frequency_hz": 77e9,
            "bandwidth_hz": 833e6,
            "range_bin_m": 0.18,
            "doppler_bin_mps": 0.1,
            "rx_positions_m": [[0.0, 0.0019 * a, 0.0] for a in range(A)],
        }
    }
}


def write_dataset(root: pathlib.Path, backend: str, frames: int) -> pathlib.Path:
    rng = np.random.default_rng(0)
    cube = (rng.standard_normal((R, D, A)) + 1j * rng.standard_normal((R, D, A))).astype(np.complex64)
    writer = DatasetWriter(root, f"bench-{backend}", backend=backend)
    origin = {"lat_deg": 37.0, "lon_deg": -122.0, "height_m": 0.0}
    with writer.scene("bench", enu_origin=origin, calibration=CALIBRATION) as scene:
        for k in range(frames):
            cube[0, 0, 0] = k  # every cube distinct
            scene.append_radar("left", T0_NS + k * 50_000_000, cube)
    writer.finalize({"train": ["bench"]})
    return root / "scenes" / f"bench{'.zarr' if backend == 'zarr' else '.h5'}"


def chunk_locations(store: pathlib.Path, backend: str, frames: int) -> list[tuple[str, int]]:
    """(file, byte offset) of every cube chunk, found through the backend's own metadata."""
    if backend == "zarr":
        array = zarr.open_array(store / "radar" / "left" / "cube", mode="r")
        base = store / "radar" / "left" / "cube"
        return [(str(base / array.metadata.encode_chunk_key((k, 0, 0, 0))), 0) for k in range(frames)]
    with h5py.File(store, "r") as handle:
        dataset = handle["radar/left/cube"]
        return [(str(store), int(dataset.id.get_chunk_info_by_coord((k, 0, 0, 0)).byte_offset)) for k in range(frames)]


def read_raw(locations: list[tuple[str, int]], batch: int) -> int:
    """Read every chunk into numpy, batch by batch; returns bytes read."""
    total = 0
    for start in range(0, len(locations), batch):
        group = locations[start : start + batch]
        out = np.empty((len(group), R, D, A), dtype=np.complex64)
        flat = out.reshape(len(group), -1).view(np.uint8)
        for row, (path, offset) in enumerate(group):
            with open(path, "rb", buffering=0) as handle:
                handle.seek(offset)
                total += handle.readinto(flat[row])
    if total != len(locations) * FRAME_BYTES:
        raise RuntimeError(f"raw read {total} bytes, expected {len(locations) * FRAME_BYTES}")
    return total


class PerItemStore(Dataset):
    """What users write today: open the store in ``__getitem__`` (or once per worker,
    ``keep_open``), read one cube, return a tensor; torch's default collate stacks them."""

    def __init__(self, store: pathlib.Path, backend: str, frames: int, keep_open: bool) -> None:
        self.store, self.backend, self.frames, self.keep_open = store, backend, frames, keep_open
        self._array = None

    def __len__(self) -> int:
        return self.frames

    def _open(self):
        if self.backend == "zarr":
            return zarr.open_array(self.store / "radar" / "left" / "cube", mode="r"), None
        handle = h5py.File(self.store, "r")
        return handle["radar/left/cube"], handle

    def __getitem__(self, index: int) -> dict:
        if self.keep_open:
            if self._array is None:  # opened in the worker that uses it (h5py handles do not survive fork)
                self._array = self._open()[0]
            return {"cube": torch.from_numpy(self._array[index])}
        array, handle = self._open()
        try:
            return {"cube": torch.from_numpy(array[index])}
        finally:
            if handle is not None:
                handle.close()


class InMemoryCubes(Dataset):
    """Items already in memory: what the DataLoader's worker transfer alone delivers."""

    def __init__(self, frames: int) -> None:
        self.frames = frames
        self.cube = np.ones((R, D, A), dtype=np.complex64)

    def __len__(self) -> int:
        return self.frames

    def __getitem__(self, index: int) -> dict:
        return {"cube": torch.from_numpy(self.cube.copy())}


def make_loader(ds: Dataset, workers: int, batch: int, collate=None) -> DataLoader:
    # Persistent workers: the timed passes measure streaming, not process start-up.
    return DataLoader(
        ds,
        batch_size=batch,
        num_workers=workers,
        collate_fn=collate,
        multiprocessing_context="fork" if workers else None,
        prefetch_factor=4 if workers else None,
        persistent_workers=workers > 0,
    )


def read_loader(loader: DataLoader, expected_bytes: int) -> int:
    total = 0
    for out in loader:
        cube = out["radar"]["left"]["cube"] if "radar" in out else out["cube"]
        total += cube.numel() * cube.element_size()
    if total != expected_bytes:
        raise RuntimeError(f"loader delivered {total} bytes, expected {expected_bytes}")
    return total


def run_backend(tmp: pathlib.Path, backend: str, args: argparse.Namespace) -> list[tuple]:
    store = write_dataset(tmp / backend, backend, args.frames)
    locations = chunk_locations(store, backend, args.frames)
    nbytes = args.frames * FRAME_BYTES
    ds = ZendarDataset(tmp / backend, split="train", streams=("radar",), reference="radar/left")
    if len(ds) != args.frames:
        raise RuntimeError(f"dataset has {len(ds)} items, expected {args.frames}")
    rows = []
    for workers in args.workers:
        loaders = {
            "ZendarDataset + collate (package)": make_loader(ds, workers, args.batch, ZendarDataset.collate),
            f"per-item {'zarr.open_array' if backend == 'zarr' else 'h5py.File'}, default collate":
                make_loader(PerItemStore(store, backend, args.frames, False), workers, args.batch),
            "handle kept per worker, default collate":
                make_loader(PerItemStore(store, backend, args.frames, True), workers, args.batch),
        }
        if workers:
            loaders["in-memory items, default collate (no I/O)"] = make_loader(InMemoryCubes(args.frames), workers, args.batch)
        fns = {"raw chunk reads into numpy (reference)": lambda: read_raw(locations, args.batch)}
        fns.update({name: (lambda loader=loader: read_loader(loader, nbytes)) for name, loader in loaders.items()})
        times = interleaved(fns, args.repeats)
        del loaders
        raw = times["raw chunk reads into numpy (reference)"]
        for name, spread in times.items():
            rows.append((backend, workers, name, spread, raw.median / spread.median, nbytes))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=96, help="cubes per backend (4 MiB each)")
    parser.add_argument("--repeats", type=int, default=7, help="timed rounds (each times every reader once)")
    parser.add_argument("--batch", type=int, default=8)
    parser.add_argument("--backend", nargs="+", choices=("zarr", "hdf5"), default=["zarr", "hdf5"])
    parser.add_argument("--workers", nargs="+", type=int, default=[0, 1, 2])
    args = parser.parse_args()

    print_environment(("torch", "numpy", "zarr", "h5py"))
    print(f"{args.frames} cubes of [{R}, {D}, {A}] complex64 ({FRAME_BYTES / 2**20:.0f} MiB each), "
          f"batch {args.batch}, {args.repeats} interleaved rounds, warm page cache")
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-loader-") as tmp:
        for backend in args.backend:
            rows += run_backend(pathlib.Path(tmp), backend, args)
    print(f"{'backend':<8}{'workers':>8}  {'method':<46}{'MB/s median (min-max)':>26}{'vs raw':>8}")
    for backend, workers, name, spread, ratio, nbytes in rows:
        rate = Spread(nbytes / spread.max / 1e6, nbytes / spread.median / 1e6, nbytes / spread.min / 1e6, spread.repeats)
        print(f"{backend:<8}{workers:>8}  {name:<46}{rate.text('.0f'):>26}{ratio:>8.2f}")
    print("target: package >= 0.80 x raw (median ratio)")
    print_load_after()


if __name__ == "__main__":
    main()
