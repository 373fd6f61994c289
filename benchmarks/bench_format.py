"""Format v1 storage claims: compression choice and radar-cube read throughput.

1. Compression: a paper-sized complex64 radar cube of receiver noise does not
   compress (ratio ~1) while costing time, so cubes and SAR images are stored raw.
2. Reading: ``SceneReader.array("radar/<r>/cube")[k]`` against the plain
   reference (each frame's chunk bytes read straight into numpy with
   ``np.fromfile``) and against the backends' own readers, from a warm page cache.

Run: ``python benchmarks/bench_format.py [--frames N]``.
"""

from __future__ import annotations

import argparse
import pathlib
import tempfile

import h5py
import numpy as np
import zarr
from harness import interleaved, print_environment, print_load_after, time_calls
from numcodecs import LZ4, Blosc, Zstd

from zendar_dataset.format import SceneReader, SceneWriter

R, D, A = 512, 256, 4
ENU_ORIGIN = {"lat_deg": 37.77, "lon_deg": -122.42, "height_m": 10.0}
CALIBRATION = {
    "sensors": {
        "left": {
            "rotation_wxyz": [1.0, 0.0, 0.0, 0.0], "translation_m": [0.0, 0.0, 0.5],
            "center_frequency_hz": 77e9, "bandwidth_hz": 833e6, "range_bin_m": 0.18,
            "doppler_bin_mps": 0.1, "rx_positions_m": [[0.0, 0.0019 * a, 0.0] for a in range(A)],
        }
    }
}


def best_of(repeats: int, work) -> float:
    """Best of ``repeats`` calls (the compression table: a single-threaded codec on one frame)."""
    return time_calls(work, repeats, warmup=0).min


def compression_table(cube: np.ndarray, image: np.ndarray) -> None:
    print("\n## Compression (one frame; ratio = raw bytes / stored bytes)")
    print(f"{'array':<26}{'codec':<22}{'ratio':>8}{'encode MB/s':>14}{'decode MB/s':>14}")
    codecs = {
        "blosc-lz4+shuffle": Blosc(cname="lz4", clevel=5, shuffle=Blosc.SHUFFLE),
        "zstd-3": Zstd(level=3),
        "lz4": LZ4(),
    }
    for label, frame in (("radar cube noise c64", cube), ("camera image u8", image)):
        raw = frame.tobytes()
        for name, codec in codecs.items():
            encoded = codec.encode(raw)
            enc = best_of(3, lambda: codec.encode(raw))
            dec = best_of(3, lambda: codec.decode(encoded))
            mb = len(raw) / 1e6
            print(f"{label:<26}{name:<22}{len(raw) / len(encoded):>8.3f}{mb / enc:>14.0f}{mb / dec:>14.0f}")


def read_table(workdir: pathlib.Path, n_frames: int, repeats: int) -> None:
    rng = np.random.default_rng(0)
    cubes = (rng.standard_normal((n_frames, R, D, A)) + 1j * rng.standard_normal((n_frames, R, D, A))).astype(np.complex64)
    total_mb = cubes.nbytes / 1e6
    print(f"\n## Reading {n_frames} radar cubes [{R},{D},{A}] complex64 ({total_mb:.0f} MB), warm cache, "
          f"{repeats} interleaved rounds, one thread each")
    print(f"{'backend':<8}{'reader':<44}{'MB/s median (min-max)':>20}{'cubes/s':>10}{'vs raw':>8}")
    for suffix in (".zarr", ".h5"):
        path = workdir / f"scene{suffix}"
        with SceneWriter(path, "bench", enu_origin=ENU_ORIGIN, calibration=CALIBRATION) as writer:
            for k in range(n_frames):
                writer.append_radar("left", 1_000_000_000 + k * 50_000_000, cubes[k])
        scene = SceneReader(path)
        cube = scene.array("radar/left/cube")
        if suffix == ".zarr":
            native = zarr.open_array(str(path / "radar/left/cube"), mode="r")
            files = [path / "radar/left/cube" / "c" / str(k) / "0" / "0" / "0" for k in range(n_frames)]

            def raw() -> None:
                for f in files:
                    np.fromfile(f, dtype=np.complex64)
        else:
            handle = h5py.File(path, "r")
            native = handle["radar/left/cube"]
            offsets = [native.id.get_chunk_info_by_coord((k, 0, 0, 0)).byte_offset for k in range(n_frames)]
            count = R * D * A

            def raw() -> None:
                for offset in offsets:
                    np.fromfile(path, dtype=np.complex64, count=count, offset=offset)

        def ours() -> None:
            for k in range(n_frames):
                cube[k]

        def backend() -> None:
            for k in range(n_frames):
                native[k]

        for f in (raw, ours, backend):
            f()  # warm the page cache and any handles
        # Interleaved: the machine is shared, so each reader sees the same moments of load.
        times = interleaved({"raw": raw, "ours": ours, "backend": backend}, repeats, warmup=0)
        t_raw = times["raw"].median
        name = "zarr" if suffix == ".zarr" else "hdf5"
        rows = (
            ("raw chunk bytes -> np.fromfile (reference)", times["raw"]),
            ("SceneReader.array(...)[k]", times["ours"]),
            (f"{type(native).__module__.split('.')[0]} array[k] (backend reader)", times["backend"]),
        )
        for label, spread in rows:
            rate = f"{total_mb / spread.median:.0f} ({total_mb / spread.max:.0f}-{total_mb / spread.min:.0f})"
            print(f"{name:<8}{label:<44}{rate:>20}{n_frames / spread.median:>10.0f}{t_raw / spread.median:>8.2f}")
        assert cube[n_frames - 1].tobytes() == cubes[-1].tobytes()
        scene.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, default=32)
    parser.add_argument("--repeats", type=int, default=15)
    args = parser.parse_args()
    print_environment(("numpy", "zarr", "h5py", "numcodecs"))
    rng = np.random.default_rng(1)
    cube = (rng.standard_normal((R, D, A)) + 1j * rng.standard_normal((R, D, A))).astype(np.complex64)
    yy, xx = np.mgrid[0:720, 0:1280]
    image = np.stack([(xx // 8) % 256, (yy // 8) % 256, ((xx + yy) // 16) % 256], axis=-1).astype(np.uint8)
    image = np.clip(image.astype(np.int16) + rng.integers(-3, 4, image.shape), 0, 255).astype(np.uint8)
    compression_table(cube, image)
    with tempfile.TemporaryDirectory() as workdir:
        read_table(pathlib.Path(workdir), args.frames, args.repeats)
    print_load_after()


if __name__ == "__main__":
    main()
