"""Claim: streaming radar cubes through ZendarDataset + DataLoader reaches >= 80 % of the
throughput of reading the same bytes raw, from a warm page cache.

For each backend (zarr, HDF5) a scene of N paper-sized cubes ([512, 256, 4]
complex64, 4 MiB) is written once. The plain reference reads every cube's chunk
bytes straight into a preallocated numpy array (zarr: the chunk file; HDF5: the
chunk's byte range, located with h5py's chunk index). The loader reads the same
cubes as items (reference = the radar, cube_window=1) through a DataLoader with
batch_size=8 and ``ZendarDataset.collate`` for 0, 1 and 2 workers (persistent, fork).
The page cache (and the workers) are warmed by one untimed pass; each figure is the
best of --repeats passes (the machine's load average is printed: figures from a busy
machine are not comparable). With workers, batches leave through each worker's pool of
recycled shared memory (zendar_dataset.shared_batches); a second row gives torch's own
worker-to-main transfer on this machine (items already in memory, torch's default
collate, a fresh shared tensor per batch), the path the pool replaces.

Run: python benchmarks/bench_loader.py [--frames 96] [--repeats 5]
"""

from __future__ import annotations

import argparse
import os
import pathlib
import tempfile
import time

import h5py
import numpy as np
import zarr
from torch.utils.data import DataLoader

from zendar_dataset import ZendarDataset
from zendar_dataset.format import DatasetWriter

R, D, A = 512, 256, 4
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
    frame_bytes = R * D * A * 8
    total = 0
    for start in range(0, len(locations), batch):
        group = locations[start : start + batch]
        out = np.empty((len(group), R, D, A), dtype=np.complex64)
        flat = out.reshape(len(group), -1).view(np.uint8)
        for row, (path, offset) in enumerate(group):
            with open(path, "rb", buffering=0) as handle:
                handle.seek(offset)
                total += handle.readinto(flat[row])
        assert total % frame_bytes == 0
    return total


def make_loader(ds: ZendarDataset, workers: int, batch: int) -> DataLoader:
    # Persistent workers: the timed passes measure streaming, not process start-up.
    return DataLoader(
        ds,
        batch_size=batch,
        num_workers=workers,
        collate_fn=ZendarDataset.collate,
        multiprocessing_context="fork" if workers else None,
        prefetch_factor=4 if workers else None,
        persistent_workers=workers > 0,
    )


def read_loader(loader: DataLoader) -> int:
    total = 0
    for out in loader:
        cube = out["radar"]["left"]["cube"]
        total += cube.numel() * cube.element_size()
    return total


class InMemoryCubes:
    """Items already in memory: what the DataLoader's worker transfer alone delivers."""

    def __init__(self, frames: int) -> None:
        self.frames = frames
        self.cube = np.ones((R, D, A), dtype=np.complex64)

    def __len__(self) -> int:
        return self.frames

    def __getitem__(self, index: int) -> dict:
        return {"radar": {"left": {"cube": self.cube[None].copy()}}}


def best_of(repeats: int, fn) -> tuple[float, int]:
    fn()  # warm the page cache and imports
    times, size = [], 0
    for _ in range(repeats):
        start = time.perf_counter()
        size = fn()
        times.append(time.perf_counter() - start)
    return min(times), size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=96, help="cubes per backend (4 MiB each)")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--batch", type=int, default=8)
    args = parser.parse_args()

    load_before = os.getloadavg()
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-loader-") as tmp:
        for backend in ("zarr", "hdf5"):
            store = write_dataset(pathlib.Path(tmp) / backend, backend, args.frames)
            locations = chunk_locations(store, backend, args.frames)
            raw_s, raw_bytes = best_of(args.repeats, lambda: read_raw(locations, args.batch))
            rows.append((backend, "raw chunk reads (numpy)", raw_s, raw_bytes, raw_s))
            ds = ZendarDataset(pathlib.Path(tmp) / backend, split="train", streams=("radar",), reference="radar/left")
            assert len(ds) == args.frames
            for workers in (0, 1, 2):
                loader = make_loader(ds, workers, args.batch)
                seconds, size = best_of(args.repeats, lambda: read_loader(loader))
                del loader
                assert size == raw_bytes
                rows.append((backend, f"ZendarDataset+DataLoader, {workers} workers", seconds, size, raw_s))
                if workers:
                    ceiling = DataLoader(
                        InMemoryCubes(args.frames), batch_size=args.batch, num_workers=workers,
                        multiprocessing_context="fork", prefetch_factor=4, persistent_workers=True,
                    )
                    seconds, size = best_of(args.repeats, lambda: read_loader(ceiling))
                    del ceiling
                    rows.append((backend, f"  in-memory items (no I/O), {workers} workers", seconds, size, raw_s))

    load_after = os.getloadavg()
    print(f"{args.frames} cubes of [{R}, {D}, {A}] complex64 ({R * D * A * 8 / 2**20:.0f} MiB each), "
          f"batch {args.batch}, best of {args.repeats}, warm page cache")
    print(f"{'backend':<8}{'method':<38}{'MB/s':>10}{'items/s':>10}{'vs raw':>9}")
    for backend, method, seconds, size, raw_s in rows:
        mb_s = size / seconds / 1e6
        items_s = args.frames / seconds
        print(f"{backend:<8}{method:<38}{mb_s:>10.0f}{items_s:>10.1f}{raw_s / seconds:>9.2f}")
    print("target: loader >= 0.80 x raw")
    print(f"load average (1 min) before {load_before[0]:.2f}, after {load_after[0]:.2f}, "
          f"on {os.cpu_count()} CPUs")


if __name__ == "__main__":
    main()
