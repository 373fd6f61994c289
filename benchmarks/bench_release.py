"""Import throughput of ``import-release`` against a plain read of the same files, in the same run.

A synthetic release scene is written once (vectorised encoders, laid out as
the fact sheet says): magnitude SAR images of two radars (bright where the
radar's 200 detections of the frame are, as on a recording), range-Doppler cubes
of paper size, lidar sweeps of 30 000 points, detections and a tracklog.  Then,
alternating, (a) a plain read of every file (``read`` into one reused buffer,
the floor for any reader), (b) a plain copy of the files into a fresh directory
(``shutil.copytree``: the input's bytes read and written once, the floor for
any importer that stores what it reads uncompressed) and (c) the full import
into a fresh format-v1 dataset (decode, convert, write, rename).  Throughput is
MB of input per second; the ratio c/a is the claim (aim: at least 0.1); c/b
says how far the import is from the copy.  The decode-only rate
(every record decoded into arrays, nothing written; aim: at least 0.3 of a plain
read) and the import's seconds by step (decode, and inside the format writer its
checks and copies, checksums, array writes and metadata) are printed too, to
show where the time goes.

Run: ``python benchmarks/bench_release.py [--sar-frames N] [--repeats R] [--keep DIR] [--variants] [--against SRC]``
(``--variants``: the import against itself with one of the choices that made it faster undone — zstd
level 3 for whole arrays, no read-ahead, the lidar read ahead by two sweeps only, the files written by
zarr — alternating in one process; ``--against SRC``: the import
of this checkout against that of another checkout of the package at ``SRC`` — e.g. a ``git worktree``
of an earlier commit — each in a process of its own, alternating, on the same release). The machine
may be shared: give enough repeats, and read the best (min) figures beside the medians.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import shutil
import statistics
import struct
import tempfile
import time

import numpy as np

from zendar_dataset.release import ReleaseStream, import_release
from zendar_dataset.release import records as rec
from zendar_dataset.release.wire import decode

T0_S = 1_264_000_000.0
ORIGIN_ECEF = np.array([-2_706_000.0, -4_261_000.0, 3_885_000.0])
SERIALS = {"1739000J1Q": 1.0, "1739000J2R": -1.0}  # lateral sign of each radar's images


def _key(number: int, wire: int) -> bytes:
    return bytes([number << 3 | wire])


def _ld(number: int, payload: bytes) -> bytes:
    length = len(payload)
    out = bytearray(_key(number, 2))
    while True:
        byte = length & 0x7F
        length >>= 7
        out.append(byte | (0x80 if length else 0))
        if not length:
            return bytes(out) + payload


def _f64(number: int, value: float) -> bytes:
    return _key(number, 1) + struct.pack("<d", value)


def _vec(v) -> bytes:
    return _f64(1, v[0]) + _f64(2, v[1]) + _f64(3, v[2])


def _varint_field(number: int, value: int) -> bytes:
    out = bytearray(_key(number, 0))
    while True:
        byte = value & 0x7F
        value >>= 7
        out.append(byte | (0x80 if value else 0))
        if not value:
            return bytes(out)


def _stream(path: pathlib.Path, records, header: bool = True) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as handle:
        if header:
            handle.write(bytes(8))
        for payload in records:
            handle.write(struct.pack("<I", len(payload)))
            handle.write(payload)


def _vec_elements(tag: int, xyz: np.ndarray) -> np.ndarray:
    """``[P]`` encoded ``tag len Vec3d`` sub-fields (29 bytes each) as a structured array."""
    dtype = np.dtype([("tag", "u1"), ("len", "u1"), ("t1", "u1"), ("x", "<f8"), ("t2", "u1"), ("y", "<f8"), ("t3", "u1"), ("z", "<f8")])
    out = np.zeros(len(xyz), dtype)
    out["tag"], out["len"], out["t1"], out["t2"], out["t3"] = tag, 27, 0x09, 0x11, 0x19
    out["x"], out["y"], out["z"] = xyz.T
    return out


def _lidar_frame(t: float, position_ecef: np.ndarray, position_local: np.ndarray, intensity: np.ndarray) -> bytes:
    """One LidarPointsFrame; intensities over 0-255 give two point layouts (a one- or two-byte varint,
    71 or 72 bytes a point), mixed in the order the points come, as in a real sweep."""
    n = len(position_ecef)
    wide = intensity >= 128
    common = np.dtype([("tag", "u1"), ("len", "u1"), ("t_ts", "u1"), ("ts", "<f8"), ("g", "V29"), ("l", "V29"), ("t_i", "u1")])
    head = np.zeros(n, common)
    head["tag"], head["t_ts"], head["t_i"] = 0x12, 0x09, 0x20
    head["len"] = np.where(wide, 70, 69)
    head["ts"] = t
    head["g"] = _vec_elements(0x12, position_ecef).view("V29")
    head["l"] = _vec_elements(0x1A, position_local).view("V29")
    varint = np.zeros((n, 2), np.uint8)
    varint[:, 0] = np.where(wide, (intensity & 0x7F) | 0x80, intensity)
    varint[:, 1] = intensity >> 7
    sizes = common.itemsize + 1 + wide
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    out = np.empty(int(sizes.sum()), np.uint8)
    out[starts[:, None] + np.arange(common.itemsize)] = head.view(np.uint8).reshape(n, common.itemsize)
    out[starts + common.itemsize] = varint[:, 0]
    out[starts[wide] + common.itemsize + 1] = varint[wide, 1]
    return _f64(1, t) + out.tobytes()


def _detection(t: float, p: np.ndarray, r: float) -> bytes:
    floats = b"".join(_key(n, 5) + struct.pack("<f", v) for n, v in ((3, 10.0), (4, 1e-4), (5, 1e-4), (6, r), (7, 0.5), (8, 0.1), (9, 0.0), (10, 12.0)))
    return _ld(1, _f64(1, t)) + _ld(2, _vec(p)) + floats


def write_release(root: pathlib.Path, sar_frames: int, rng: np.random.Generator) -> int:
    scene = root / "2020-02-03_2252" / "001"
    rows, cols = 512, 512
    attitude = _f64(1, 0.5) + _f64(2, -0.5) + _f64(3, 0.5) + _f64(4, -0.5)
    for serial, side in SERIALS.items():
        images, states = [], []
        for k in range(sar_frames):
            t = T0_S + k / 10
            position = ORIGIN_ECEF + [0.8 * k, 0.0, 0.0]
            origin = position + [0.0, side * 5.0, 0.0]
            pixels = rng.integers(0, 1000, size=rows * cols, dtype="<u4")
            # The radar's own detections in the image (as on a recording, where they are its bright
            # returns): bright pixels in the SDK viewer's order (flat j·rows + i), the detections at their
            # ECEF positions; so the pixel-order check decides on them, as on a recording.
            hit_i, hit_j = rng.integers(0, rows, 200), rng.integers(0, cols, 200)
            pixels[hit_j * rows + hit_i] = rng.integers(50_000, 100_000, 200)
            pixels = pixels.tobytes()
            model = _ld(1, _vec(origin)) + _ld(2, _vec((0.04, 0.0, 0.0))) + _ld(3, _vec((0.0, side * 0.04, 0.0)))
            data = _varint_field(1, 5) + _varint_field(2, rows) + _varint_field(3, cols) + _ld(4, pixels)
            images.append(
                _f64(1, t) + _ld(2, attitude) + _ld(3, _vec(position)) + _varint_field(4, k) + _ld(10, _ld(1, model) + _ld(2, data))
            )
            hits = origin + np.outer(hit_i, (0.04, 0.0, 0.0)) + np.outer(hit_j, (0.0, side * 0.04, 0.0))
            points = [_ld(2, _detection(t, hits[d], 10.0 + d)) for d in range(200)]
            states.append(_ld(1, _f64(1, t)) + b"".join(points) + _varint_field(3, k))
        _stream(scene / f"{serial}_images.pbs", images)
        _stream(scene / f"{serial}_points.pbs", states)
    poses = [
        _f64(1, T0_S + k / 200) + _ld(2, attitude) + _ld(3, _vec(ORIGIN_ECEF + [0.04 * k, 0.0, 0.0])) + _varint_field(4, k)
        for k in range(sar_frames * 20)
    ]
    _stream(scene / "vn200.pbs", poses)
    sweeps = []
    for k in range(sar_frames):
        local = rng.normal(scale=20.0, size=(30_000, 3))
        sweeps.append(_lidar_frame(T0_S + k / 10, ORIGIN_ECEF + local, local, rng.integers(0, 256, 30_000)))
    _stream(scene / "lidar" / "00" / "stream.pbs", sweeps, header=False)
    R, D, A = 512, 256, 4
    model = (
        _varint_field(1, A)
        + _ld(2, _f64(1, 0.0) + _f64(2, 0.176) + _varint_field(3, R))
        + _ld(3, _f64(1, -D / 2 * 0.1) + _f64(2, 0.1) + _varint_field(3, D))
        + b"".join(_ld(4, _vec((0.0019 * a, 0.0, 0.0))) for a in range(A))
        + _f64(5, 0.0039)
    )
    _stream(scene / "range_Doppler" / "left_model.pbs", [model])
    cube = (rng.normal(size=(R, D, A)) + 1j * rng.normal(size=(R, D, A))).astype("<c8").tobytes()
    _stream(scene / "range_Doppler" / "left_rd.pbs", [_f64(1, T0_S + k / 20) + _ld(2, cube) for k in range(sar_frames // 2)])
    return sum(p.stat().st_size for p in root.rglob("*.pbs"))


def plain_read(root: pathlib.Path) -> None:
    buffer = bytearray(16 * 2**20)
    view = memoryview(buffer)
    for path in sorted(root.rglob("*.pbs")):
        with open(path, "rb", buffering=0) as handle:
            while handle.readinto(view):
                pass


def decode_only(root: pathlib.Path) -> None:
    """Every record of every stream into arrays, as the import decodes them (the tracklog column-wise,
    detections and lidar sweeps through their column decoders, SAR images as C-order grids), nothing written."""
    for path in sorted(root.rglob("*.pbs")):
        with ReleaseStream(path) as stream:
            kind = stream.kind
            if kind.name == "Position":
                _, offsets, lengths = stream.spans()
                rec.poses(stream.buffer, offsets, lengths)
                continue
            for _, buf, start, end in stream.records():
                if kind.name == "TrackerState":
                    rec.detections(kind, buf, start, end)
                elif kind.name == "LidarPointsFrame":
                    rec.lidar_sweep(kind, buf, start, end)
                elif kind.name == "Image":
                    np.ascontiguousarray(rec.sar_grid(rec.sar_frame_record(kind, buf, start, end))[0])
                else:
                    decoded = decode(kind.message, buf, start, end)
                    if kind.name == "RangeDopplerFrame":
                        np.frombuffer(decoded["data"], "<c8")


class WriterClock:
    """Seconds spent inside ``SceneWriter`` (appends, whole-array writes, close): the format's share of an
    import, and within it the seconds in checksums, array writes and metadata; the rest is its checks.
    Whole arrays' files (``stores._staged_files``: their metadata and encoded chunks, made in memory) count
    as array writes, as do the lidar's chunk files (``stores.write_rows``); attribute merges as metadata."""

    METHODS = ("append_sar", "append_radar", "append_lidar", "write_tracklog", "write_detections",
               "write_camera_index", "write_extra_array", "write_attrs", "close", "__init__")

    def __init__(self) -> None:
        import zarr

        from zendar_dataset.format import checksums, stores
        from zendar_dataset.format.writer import SceneWriter

        self.seconds = 0.0
        self.parts = {"checksums": 0.0, "array writes": 0.0, "metadata": 0.0}
        self._in_part = False
        targets = {
            "checksums": [(checksums, "crc32c"), (checksums, "block_checksums"), (checksums, "encode")],
            "array writes": [(zarr.Array, "__setitem__"), (stores, "write_raw_frame"), (stores, "fill_arrays"),
                             (stores, "_write_file"), (stores, "_staged_files"), (stores, "write_rows")],
            "metadata": [(stores, "create_array"), (stores, "create_arrays"), (stores, "write_attrs"), (stores, "consolidate"),
                         (stores, "merge_attrs"), (zarr.Array, "resize")],
        }
        self.saved = [(SceneWriter, name, getattr(SceneWriter, name)) for name in self.METHODS]
        for owner, name, method in self.saved:
            setattr(owner, name, self._timed(method))
        for part, where in targets.items():
            for owner, name in where:
                self.saved.append((owner, name, getattr(owner, name)))
                setattr(owner, name, self._timed_part(part, getattr(owner, name)))

    def _timed(self, method):
        def timed(*args, **kwargs):
            start = time.perf_counter()
            try:
                return method(*args, **kwargs)
            finally:
                self.seconds += time.perf_counter() - start

        return timed

    def _timed_part(self, part: str, function):
        def timed(*args, **kwargs):
            if self._in_part:  # nested (a checksum helper calling another): counted once, by the outer call
                return function(*args, **kwargs)
            self._in_part = True
            start = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                self.parts[part] += time.perf_counter() - start
                self._in_part = False

        return timed

    def restore(self) -> None:
        for owner, name, method in reversed(self.saved):
            setattr(owner, name, method)


def compare_variants(sar_frames: int, repeats: int) -> None:
    """The import as it is, and with choices that made it faster undone one at a time: zstd level 3 (the
    level before) for the format's whole arrays; every stream's records decoded in line instead of read
    ahead on a second thread; the lidar read ahead by two sweeps only, as the other streams are, instead of
    decoded from the start of the scene beside the writing of the images and cubes; whole arrays and lidar
    chunks written by zarr instead of made directly (``format/zarr_files.py``). Alternating run by run, in
    this process, on the same release."""
    import contextlib

    from zarr.codecs import ZstdCodec

    from zendar_dataset.format import stores, zarr_files
    from zendar_dataset.release import importer

    print(f"load average before: {os.getloadavg()}")
    work = pathlib.Path(tempfile.mkdtemp(prefix="bench_release_"))
    current = (stores._ZARR_COMPRESSORS[stores.SMALL], importer.read_ahead, importer.LIDAR_READ_AHEAD_BYTES,
               importer._lidar_read_ahead, zarr_files.chunk_files)

    def lidar_in_line(lidars, enu):
        return contextlib.nullcontext(importer._lidar_sweeps(lidars, enu))

    variants = {
        "as it is": current,
        "zstd level 3": ((ZstdCodec(level=3),), *current[1:]),
        "no read-ahead": (current[0], lambda records: records, current[2], lidar_in_line, current[4]),
        "lidar 2 ahead": (*current[:2], 0, *current[3:]),
        "files by zarr": (*current[:4], lambda *args, **kwargs: None),
    }
    try:
        src = work / "release"
        size = write_release(src, sar_frames, np.random.default_rng(0))
        print(f"release: {size / 1e6:.1f} MB in {len(list(src.rglob('*.pbs')))} streams")
        import_release(src, work / "warm", log=None)
        shutil.rmtree(work / "warm")
        times: dict[str, list[float]] = {name: [] for name in variants}
        for _ in range(repeats):
            for name, variant in variants.items():
                (stores._ZARR_COMPRESSORS[stores.SMALL], importer.read_ahead, importer.LIDAR_READ_AHEAD_BYTES,
                 importer._lidar_read_ahead, zarr_files.chunk_files) = variant
                stores._TEMPLATES.clear()  # made with the compressors of the variant before
                out = work / "out"
                start = time.perf_counter()
                import_release(src, out, log=None)
                times[name].append(time.perf_counter() - start)
                shutil.rmtree(out)
        for name, seconds in times.items():
            print(f"{name:<14} median {statistics.median(seconds):.3f} s, best {min(seconds):.3f} s "
                  f"({size / 1e6 / statistics.median(seconds):.0f} MB/s median; of {len(seconds)})")
    finally:
        (stores._ZARR_COMPRESSORS[stores.SMALL], importer.read_ahead, importer.LIDAR_READ_AHEAD_BYTES,
         importer._lidar_read_ahead, zarr_files.chunk_files) = current
        shutil.rmtree(work, ignore_errors=True)
        print(f"load average after: {os.getloadavg()}")


# Run in a fresh process for --against: imports the release (argv[1]) into argv[2] twice (the first
# warms the numba cache and the page cache), prints the second's seconds, then (_WHICH) the folder the
# package was imported from, which the caller checks.
_TIMED_IMPORT = """
import shutil, sys, time
from zendar_dataset.release import import_release
src, out = sys.argv[1:3]
import_release(src, out, log=None)
shutil.rmtree(out)
start = time.perf_counter()
import_release(src, out, log=None)
print(time.perf_counter() - start)
shutil.rmtree(out)
"""
_WHICH = """
import os, zendar_dataset
print(os.path.dirname(zendar_dataset.__file__))
"""


def compare_checkouts(sar_frames: int, repeats: int, other: pathlib.Path) -> None:
    """The import of this checkout against that of the package checked out at ``other``, alternating,
    each timed in a process of its own (``PYTHONPATH`` puts the checkout first)."""
    import subprocess
    import sys

    if not (other / "zendar_dataset" / "__init__.py").is_file():
        raise SystemExit(f"--against {other}: expected a checkout of the package (zendar_dataset/ in it)")
    here = pathlib.Path(__file__).resolve().parents[1]
    print(f"load average before: {os.getloadavg()}")
    work = pathlib.Path(tempfile.mkdtemp(prefix="bench_release_"))
    try:
        src = work / "release"
        size = write_release(src, sar_frames, np.random.default_rng(0))
        print(f"release: {size / 1e6:.1f} MB in {len(list(src.rglob('*.pbs')))} streams")
        times: dict[str, list[float]] = {"this checkout": [], str(other): []}
        for _ in range(repeats):
            for name, checkout in (("this checkout", here), (str(other), other)):
                env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(checkout), os.environ.get("PYTHONPATH", "")])}
                # cwd: ``-c`` puts the working folder first on the path, before PYTHONPATH.
                done = subprocess.run([sys.executable, "-c", _TIMED_IMPORT + _WHICH, str(src), str(work / "out")],
                                      env=env, cwd=work, capture_output=True, text=True, check=True)
                found = pathlib.Path(done.stdout.split()[-1]).resolve()
                if found != checkout / "zendar_dataset":
                    raise SystemExit(f"--against: the process for {checkout} imported the package from {found}")
                times[name].append(float(done.stdout.split()[-2]))
        for name, seconds in times.items():
            print(f"{name:<14} median {statistics.median(seconds):.3f} s, best {min(seconds):.3f} s "
                  f"({size / 1e6 / statistics.median(seconds):.0f} MB/s median; of {len(seconds)})")
        ratio = statistics.median(times[str(other)]) / statistics.median(times["this checkout"])
        print(f"this checkout is {ratio:.2f}x as fast (medians)")
    finally:
        shutil.rmtree(work, ignore_errors=True)
        print(f"load average after: {os.getloadavg()}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sar-frames", type=int, default=40, help="SAR frames per radar (default 40)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--keep", type=pathlib.Path, default=None, help="write the release here and keep it")
    parser.add_argument("--variants", action="store_true",
                        help="instead: the import as it is against it with zstd level 3 for whole arrays, without "
                             "the read-ahead, with the lidar read ahead by two sweeps only, or with the files written "
                             "by zarr, alternating in one process")
    parser.add_argument("--against", type=pathlib.Path, default=None, metavar="SRC",
                        help="instead: this checkout's import against that of the checkout at SRC, alternating")
    args = parser.parse_args()
    if args.against is not None:
        compare_checkouts(args.sar_frames, args.repeats, args.against.resolve())
        return
    if args.variants:
        compare_variants(args.sar_frames, args.repeats)
        return
    print(f"load average before: {os.getloadavg()}")
    work = pathlib.Path(tempfile.mkdtemp(prefix="bench_release_"))
    src = args.keep or work / "release"
    try:
        size = write_release(src, args.sar_frames, np.random.default_rng(0))
        print(f"release: {size / 1e6:.1f} MB in {len(list(src.rglob('*.pbs')))} streams")
        import_release(src, work / "warm", log=None)  # compile the numba scanner, warm the page cache
        shutil.rmtree(work / "warm")
        plain, copy, full, decode, in_writer, parts = [], [], [], [], [], []
        for r in range(args.repeats):
            start = time.perf_counter()
            plain_read(src)
            plain.append(time.perf_counter() - start)
            start = time.perf_counter()
            shutil.copytree(src, work / f"copy{r}")
            copy.append(time.perf_counter() - start)
            shutil.rmtree(work / f"copy{r}")
            start = time.perf_counter()
            decode_only(src)
            decode.append(time.perf_counter() - start)
            out = work / f"out{r}"
            clock = WriterClock()
            start = time.perf_counter()
            try:
                import_release(src, out)
            finally:
                clock.restore()
            full.append(time.perf_counter() - start)
            in_writer.append(clock.seconds)
            parts.append(clock.parts)
            shutil.rmtree(out)
        mb = size / 1e6
        for label, times in (("plain read", plain), ("plain copy", copy), ("decode only", decode), ("import-release", full)):
            print(f"{label:<16} {mb / statistics.median(times):8.1f} MB/s median, {mb / min(times):8.1f} MB/s best  "
                  f"(of {len(times)}; min {min(times):.3f} s, median {statistics.median(times):.3f} s, max {max(times):.3f} s)")
        for label, times in (("import", full), ("decode only", decode), ("plain copy", copy)):
            print(f"{label} / plain read: {statistics.median(plain) / statistics.median(times):.3f} (medians), "
                  f"{min(plain) / min(times):.3f} (bests)")
        print(f"import / plain copy: {statistics.median(copy) / statistics.median(full):.3f} (medians), "
              f"{min(copy) / min(full):.3f} (bests)")
        share = statistics.median(w / f for w, f in zip(in_writer, full))
        print(f"share of the import spent in the format writer (SceneWriter): {share:.0%}; the import's seconds "
              f"(median of {len(full)}):")
        steps = {
            "decode (outside the writer)": [f - w for f, w in zip(full, in_writer)],
            "writer: checks, copies, rest": [w - sum(p.values()) for w, p in zip(in_writer, parts)],
            **{f"writer: {name}": [p[name] for p in parts] for name in parts[0]},
        }
        for label, seconds in steps.items():
            print(f"  {label:<30} {statistics.median(seconds):6.3f} s  "
                  f"{statistics.median(s / f for s, f in zip(seconds, full)):4.0%}")
    finally:
        shutil.rmtree(work, ignore_errors=True)
        print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
