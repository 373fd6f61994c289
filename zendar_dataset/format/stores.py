"""The two storage backends of format v1: Zarr v3 directories and HDF5 files.

Both hold the same hierarchy.  This module hides their few differences from
the writer, reader, validator and converter:

- object-valued attributes are native JSON in zarr and JSON strings in HDF5;
- how arrays are created (chunks, compression, a resizable first axis);
- how a store is opened from a local path or an fsspec URL;
- which exceptions mean "stored bytes could not be decoded".

Compression is chosen per kind of array (measured in ``benchmarks/bench_format.py``):
complex radar cubes and SAR images are noise-like and do not compress, so they
are stored raw and read at page-cache speed; camera images and lidar points use
a fast byte-shuffling compressor (Blosc-LZ4 in zarr, LZF in HDF5); the small
per-frame arrays use the backends' default lossless compressors.
"""

from __future__ import annotations

import asyncio
import json
import os
import pathlib
import sys
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import fsspec
import h5py
import numpy as np
import zarr
import zarr.storage
from zarr.codecs import BloscCodec, ZstdCodec
from zarr.core.buffer import default_buffer_prototype
from zarr.core.sync import sync

from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.format import zarr_files
from zendar_dataset.format.guarded_file import GuardedFile

BACKENDS = ("zarr", "hdf5")
SUFFIX_BACKEND = {".zarr": "zarr", ".h5": "hdf5", ".hdf5": "hdf5"}

RAW = "raw"
FAST = "fast"
SMALL = "small"

# Exceptions a backend raises when stored bytes are truncated or corrupt.
# IndexError/KeyError are deliberately absent: they mean a bad request, not bad data.
DECODE_ERRORS: tuple[type[BaseException], ...] = (ValueError, RuntimeError, OSError, TypeError, EOFError)

# Zstd level 1 for the whole arrays: an imported lidar's ``position_ecef`` (float64 ECEF, full mantissas)
# is the largest of them, and level 3 compressed it at ~125 MB/s against ~640 MB/s for level 1 (ratio
# 1.25 against 1.16), the single largest cost of an import after the raw frames.
_ZARR_COMPRESSORS = {
    RAW: None,
    FAST: (BloscCodec(cname="lz4", clevel=5, shuffle="shuffle"),),
    SMALL: (ZstdCodec(level=1),),
}
_HDF5_COMPRESSION = {
    RAW: {},
    FAST: {"compression": "lzf", "shuffle": True},
    SMALL: {"compression": "gzip", "compression_opts": 4, "shuffle": True},
}


def array_kind(path: str) -> str:
    """How the reference writer compresses the array at ``path`` in a scene (``group/sensor/name``):
    RAW for radar cubes and SAR images, FAST for camera images and lidar points and their ECEF
    positions, SMALL for the rest (docs/format.md: compression is otherwise free).

    Lidar ``position_ecef`` is as large as the points: Blosc-LZ4 with byte shuffling measured ~6x
    faster than zstd level 1 on float64 ECEF (5.0 against 0.85 GB/s) and smaller (ratio 1.59 against
    1.16), its high bytes being nearly constant."""
    group, _, rest = path.partition("/")
    name = rest.rsplit("/", 1)[-1]
    if (group, name) in (("radar", "cube"), ("sar", "image")):
        return RAW
    if (group, name) in (("camera", "image"), ("lidar", "points"), ("lidar", "position_ecef")):
        return FAST
    return SMALL


def backend_from_path(path: str | os.PathLike) -> str:
    """Backend named by a store's suffix: ``.zarr`` → zarr, ``.h5``/``.hdf5`` → hdf5."""
    suffix = pathlib.PurePosixPath(str(path).rstrip("/")).suffix.lower()
    if suffix not in SUFFIX_BACKEND:
        raise ValueError(f"{path}: cannot tell the backend from the suffix {suffix!r}; expected .zarr or .h5")
    return SUFFIX_BACKEND[suffix]


def is_url(location: str | os.PathLike) -> bool:
    """True for fsspec URLs other than plain local files (``s3://``, ``http://`` …)."""
    text = str(location)
    return "://" in text and not text.startswith("file://")


def local_path(location: str | os.PathLike) -> str:
    text = str(location)
    return text[len("file://"):] if text.startswith("file://") else text


def join_location(root: str, relative: str) -> str:
    """``root/relative`` for local paths and URLs alike."""
    if is_url(root):
        return root.rstrip("/") + "/" + relative.lstrip("/")
    return str(pathlib.Path(local_path(root)) / relative)


@dataclass
class OpenStore:
    """An open scene store: its root group plus whatever must be closed with it."""

    backend: str
    root: Any
    _closers: list = field(default_factory=list)
    _guard: GuardedFile | None = None

    def raise_if_failed(self) -> None:
        """Raise the OS error of a failed write into the store (HDF5: held back from the library)."""
        if self._guard is not None:
            self._guard.raise_if_failed()

    def close(self) -> None:
        # Last first; each closer is dropped before it runs, so one that raises leaves the rest to a later close.
        while self._closers:
            self._closers.pop()()


class _FileNamingLocalStore(zarr.storage.LocalStore):
    """A zarr ``LocalStore`` whose failed writes name the file, so a full disk names the store's path.

    The OS error of a raw write carries no filename (``[Errno 28] No space left on device``);
    it is raised again naming the file written, as :class:`GuardedFile` does for HDF5 stores.
    """

    async def set(self, key: str, value: Any) -> None:
        with _naming_file(self.root / key):
            await super().set(key, value)

    async def set_if_not_exists(self, key: str, value: Any) -> None:
        with _naming_file(self.root / key):
            await super().set_if_not_exists(key, value)


@contextmanager
def _naming_file(path: pathlib.Path) -> Iterator[None]:
    """Raise an OS error that names no file again, naming ``path``."""
    try:
        yield
    except OSError as exc:
        if exc.filename is not None:
            raise
        raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from exc


def create_store(path: pathlib.Path, backend: str) -> OpenStore:
    """Create an empty store at ``path`` (which must not exist) for writing."""
    if backend == "zarr":
        root = zarr.open_group(_FileNamingLocalStore(str(path)), mode="w-", zarr_format=3)
        return OpenStore(backend, root)
    if backend == "hdf5":
        guard = GuardedFile(path)
        try:
            handle = h5py.File(guard, "w-", libver=("earliest", "latest"))
        except BaseException:
            guard.close()
            raise
        return OpenStore(backend, handle, [guard.close, handle.close], guard)
    raise ValueError(f"unknown backend {backend!r}; expected one of {BACKENDS}")


def consolidate(path: pathlib.Path) -> None:
    """Write zarr consolidated metadata, so a remote reader opens a scene in one request.

    Consolidated metadata is a zarr-python convention, not yet part of the Zarr v3
    specification (hence the warning we silence); other readers ignore it, and
    ours uses it only for URLs (local metadata reads are cheap and always current).

    zarr computes it from a copy of every node's metadata file in memory, read here with plain file
    reads (zarr's walk of a local store hands each read to a worker thread: ~20 ms for a scene against
    ~10 ms); the root's metadata file is then written back with it.
    """
    buffer = default_buffer_prototype().buffer
    files = {key: buffer.from_bytes(data) for key, data in _metadata_files(pathlib.Path(path))}
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Consolidated metadata is currently not part")
        zarr.consolidate_metadata(zarr.storage.MemoryStore(files))
    _write_file(pathlib.Path(path) / "zarr.json", files["zarr.json"].to_bytes())


def _metadata_files(root: pathlib.Path, prefix: str = "") -> Iterator[tuple[str, bytes]]:
    """(key, bytes) of the ``zarr.json`` of ``root`` and of every node below it (groups are entered,
    arrays are not: their folders hold chunks)."""
    with _naming_file(root / "zarr.json"):
        data = (root / "zarr.json").read_bytes()
    yield f"{prefix}zarr.json", data
    if json.loads(data).get("node_type") != "group":
        return
    for entry in sorted(os.scandir(root), key=lambda e: e.name):
        if entry.is_dir() and os.path.isfile(os.path.join(entry.path, "zarr.json")):
            yield from _metadata_files(pathlib.Path(entry.path), f"{prefix}{entry.name}/")


def open_store(
    location: str | os.PathLike, storage_options: dict | None = None, *, consolidated: bool | None = None
) -> OpenStore:
    """Open a scene store read-only from a local path or an fsspec URL.

    ``consolidated`` (zarr only): use consolidated metadata; by default for URLs
    when present, never for local paths.
    """
    backend = backend_from_path(location)
    if consolidated is None:
        consolidated = None if is_url(location) else False
    if backend == "zarr":
        if is_url(location):
            store = zarr.storage.FsspecStore.from_url(
                str(location), storage_options=dict(storage_options or {}), read_only=True
            )
        else:
            path = local_path(location)
            if not os.path.isdir(path):
                raise FileNotFoundError(path)
            store = zarr.storage.LocalStore(path, read_only=True)
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="Consolidated metadata is currently not part")
            root = zarr.open_group(store, mode="r", zarr_format=3, use_consolidated=consolidated)
        return OpenStore(backend, root)
    if is_url(location):
        fs, fs_path = fsspec.core.url_to_fs(str(location), **(storage_options or {}))
        file_object = fs.open(fs_path, "rb")
        try:
            handle = h5py.File(file_object, "r")
        except BaseException:
            file_object.close()  # not an HDF5 file (or interrupted): nothing else will close it
            raise
        return OpenStore(backend, handle, [file_object.close, handle.close])
    handle = h5py.File(local_path(location), "r")
    return OpenStore(backend, handle, [handle.close])


def is_zarr(node: Any) -> bool:
    return isinstance(node, (zarr.Array, zarr.Group))


def is_array(node: Any) -> bool:
    return isinstance(node, (zarr.Array, h5py.Dataset))


def is_group(node: Any) -> bool:
    return isinstance(node, (zarr.Group, h5py.Group))


class MetadataError(ZendarFormatError):
    """A node's metadata cannot be read (truncated JSON, an unknown dtype or codec, a negative shape …)."""


# What the backends raise for unreadable metadata; zarr's own errors derive from ValueError.
_METADATA_ERRORS = (ValueError, TypeError, RuntimeError, OSError, RecursionError, ZeroDivisionError)


def get_node(group: Any, path: str) -> Any | None:
    """The array or group at ``path`` under ``group``, or None when absent.

    Raises :class:`MetadataError` (message starting with ``path``) when its metadata is unreadable.
    """
    try:
        node = group[path]
    except KeyError:
        return None
    except _METADATA_ERRORS as exc:
        raise MetadataError(f"{path}: expected readable metadata, found {type(exc).__name__}: {exc}") from None
    if isinstance(node, zarr.Array):
        chunks = node.chunks or ()
        if any(int(c) < 1 for c in chunks):
            raise MetadataError(f"{path}: expected a chunk shape of positive sizes, found {list(chunks)}")
    return node


def member_names(group: Any) -> list[str]:
    """Sorted names of the direct children of a group.

    For zarr the names come from the store listing (unless the group was opened
    from consolidated metadata), so that one child with unreadable metadata does
    not hide its siblings (:func:`get_node` reports it).
    """
    if isinstance(group, zarr.Group) and group.metadata.consolidated_metadata is None:
        prefix = group.store_path.path
        entries = sync(_list_dir(group.store_path.store, prefix))
        base = f"{prefix}/" if prefix else ""
        return sorted(e for e in entries if e != "zarr.json" and sync(group.store_path.store.exists(f"{base}{e}/zarr.json")))
    return sorted(group.keys())


async def _list_dir(store: Any, prefix: str) -> list[str]:
    return [key async for key in store.list_dir(prefix)]


def walk(group: Any, prefix: str = "") -> list[tuple[str, Any]]:
    """Every (path, node) below ``group`` in sorted order, groups before their children."""
    out = []
    for name in member_names(group):
        path = f"{prefix}{name}"
        try:
            node = get_node(group, name)
        except MetadataError as exc:
            raise MetadataError(f"{prefix}{exc}") from None
        out.append((path, node))
        if is_group(node):
            out.extend(walk(node, path + "/"))
    return out


def unreadable_metadata(group: Any, prefix: str = "") -> list[str]:
    """A :class:`MetadataError` message for every node below ``group`` whose metadata is unreadable.

    Unlike :func:`walk` it goes on past such a node (without entering it), so each is listed.
    """
    found = []
    for name in member_names(group):
        try:
            node = get_node(group, name)
        except MetadataError as exc:
            found.append(f"{prefix}{exc}")
            continue
        if is_group(node):
            found.extend(unreadable_metadata(node, f"{prefix}{name}/"))
    return found


def require_group(root: Any, path: str) -> Any:
    return root.require_group(path)


def create_array(
    root: Any,
    path: str,
    *,
    shape: tuple[int, ...],
    dtype: np.dtype,
    chunks: tuple[int, ...],
    kind: str,
    resizable: bool,
) -> Any:
    """Create an array; ``resizable`` makes its first axis growable (HDF5 needs to know)."""
    chunks = tuple(max(1, int(c)) for c in chunks)
    if isinstance(root, zarr.Group):
        # write_empty_chunks: an all-zero frame is still stored, so "every chunk
        # exists" is a check the validator can make.
        return root.create_array(
            path,
            shape=shape,
            dtype=dtype,
            chunks=chunks,
            compressors=_ZARR_COMPRESSORS[kind],
            fill_value=0,
            config={"write_empty_chunks": True},
        )
    # HDF5 refuses a chunk larger than a fixed shape, so an empty array must be resizable too.
    maxshape = (None, *shape[1:]) if (resizable or (shape and shape[0] == 0)) else shape
    return root.create_dataset(
        path, shape=shape, dtype=dtype, chunks=chunks, maxshape=maxshape, **_HDF5_COMPRESSION[kind]
    )


@dataclass
class NewArray:
    """An array to create and fill whole (:func:`write_arrays`)."""

    path: str
    data: np.ndarray
    chunks: tuple[int, ...]
    kind: str
    attributes: dict[str, Any] = field(default_factory=dict)


def write_arrays(root: Any, arrays: list[NewArray]) -> None:
    """Create and fill several fixed-shape arrays, with their attributes.

    In zarr every array is created (its attributes in the same metadata write) and then every one filled,
    each step concurrently in one pass through zarr's event loop: one at a time, each creation and each
    write is a round trip of several file operations, most of the time of writing a scene's ~40 small
    arrays. In a local store the files are made in memory, zarr's own bytes without its event loop, and
    written directly (:func:`_write_arrays_staged`). HDF5 writes them one after the other.
    """
    if not isinstance(root, zarr.Group):
        for a in arrays:
            target = create_array(root, a.path, shape=a.data.shape, dtype=a.data.dtype, chunks=a.chunks, kind=a.kind, resizable=False)
            if a.data.size:
                target[...] = a.data
            write_attrs(target, a.attributes)
        return

    if not arrays:
        return
    if is_local_zarr(root):
        _write_arrays_staged(root, arrays)
    else:
        fill_arrays(create_arrays(root, arrays), arrays)


def is_local_zarr(root: Any) -> bool:
    """Whether ``root`` is a zarr group in a local directory."""
    return isinstance(root, zarr.Group) and isinstance(root.store, zarr.storage.LocalStore)


def _write_arrays_staged(root: zarr.Group, arrays: list[NewArray]) -> None:
    """:func:`write_arrays` into a local store: every file of the arrays (metadata and encoded chunks) is
    made in memory (:func:`_staged_files`), then written as a plain file, each folder made once.

    zarr's local store hands every file operation to a worker thread and makes each file's folders
    anew; the ~40 small arrays of a scene took 60-100 ms that way, about half of importing a short
    recording (docs/release.md). Group metadata made for the folders above an array is written only
    where no group exists yet, so a group's attributes are kept.
    """
    base = pathlib.Path(root.store.root) / root.store_path.path
    array_folders = {a.path.strip("/") for a in arrays}
    for folder in sorted(array_folders):
        if (base / folder / "zarr.json").exists():
            raise FileExistsError(f"{base / folder}: a node is stored there already")
    files = _staged_files(arrays)
    made_dirs = {base}
    # The groups above the arrays first, top down.
    groups = sorted(
        (key.rpartition("/")[0] for key in files if key.endswith("/zarr.json") and key.rpartition("/")[0] not in array_folders),
        key=lambda folder: (folder.count("/"), folder),
    )
    for folder in groups:
        try:
            _write_file(base / folder / "zarr.json", files[f"{folder}/zarr.json"], made_dirs, exclusive=True)
        except FileExistsError:
            _require_group_metadata(base / folder / "zarr.json")  # an existing group keeps its own attributes
    written = {f"{folder}/zarr.json" for folder in groups}
    for key in sorted(files.keys() - written):
        _write_file(base / key, files[key], made_dirs)


def _staged_files(arrays: list[NewArray]) -> dict[str, bytes]:
    """Every file of ``arrays`` and of the groups above them (store-relative key -> bytes): made from
    zarr's own metadata for arrays of their kind (:mod:`zendar_dataset.format.zarr_files`), or by zarr in
    a ``MemoryStore`` for an array whose codecs that module does not make."""
    files: dict[str, bytes] = {}
    through_zarr = []
    for a in arrays:
        template, group = _zarr_templates(a.data.dtype, a.data.ndim, a.kind)
        chunks = tuple(max(1, int(c)) for c in a.chunks)
        made = zarr_files.array_files(a.path.strip("/"), a.data, chunks, a.attributes, template)
        if made is None:
            through_zarr.append(a)
            continue
        files.update(made)
        parts = a.path.strip("/").split("/")
        for depth in range(1, len(parts)):
            files.setdefault("/".join(parts[:depth]) + "/zarr.json", group)
    if through_zarr:
        staged: dict[str, Any] = {}
        fill_arrays(create_arrays(zarr.open_group(zarr.storage.MemoryStore(staged), mode="w-", zarr_format=3), through_zarr), through_zarr)
        # The staging root's ``zarr.json`` is the store's, there already.
        files.update({key: value.to_bytes() for key, value in staged.items() if key != "zarr.json"})
    return files


# Keyed by kind: a kind's compressors (_ZARR_COMPRESSORS) are constants (the benchmark that swaps them clears this).
_TEMPLATES: dict[tuple[str, int, str], tuple[dict[str, Any], dict[str, Any]]] = {}


def _zarr_templates(dtype: np.dtype, ndim: int, kind: str) -> tuple[dict[str, Any], bytes]:
    """The metadata zarr writes for an array of ``dtype``, rank ``ndim`` and ``kind`` made by
    :func:`create_arrays` (its document) and for a group above such an array (its bytes). Made by zarr
    once per process and kind."""
    key = (np.dtype(dtype).str, ndim, kind)
    if key not in _TEMPLATES:
        staged: dict[str, Any] = {}
        root = zarr.open_group(zarr.storage.MemoryStore(staged), mode="w-", zarr_format=3)
        create_arrays(root, [NewArray("group/array", np.zeros((1,) * ndim, dtype), (1,) * ndim, kind)])
        _TEMPLATES[key] = (json.loads(staged["group/array/zarr.json"].to_bytes()), json.loads(staged["group/zarr.json"].to_bytes()))
    array, group = _TEMPLATES[key]
    return array, json.dumps(group, indent=zarr.config.get("json_indent"), allow_nan=True).encode()


def _require_group_metadata(path: pathlib.Path) -> None:
    """Raise FileExistsError unless the metadata file ``path`` is a group's (an array cannot hold nodes)."""
    try:
        node_type = json.loads(path.read_bytes()).get("node_type")
    except (ValueError, AttributeError):
        node_type = None
    if node_type != "group":
        raise FileExistsError(f"{path.parent}: expected a group there to hold arrays, found {node_type or 'unreadable metadata'}")


def _write_file(path: pathlib.Path, value: bytes | memoryview, made_dirs: set[pathlib.Path] | None = None,
                exclusive: bool = False) -> None:
    """Write ``value`` as the file ``path``, first making its folders not in ``made_dirs`` (when given; see
    :func:`_make_dirs`); an OS error names the file."""
    with _naming_file(path):
        if made_dirs is not None:
            _make_dirs(path.parent, made_dirs)
        with open(path, "xb" if exclusive else "wb") as handle:
            handle.write(value)


def create_arrays(root: zarr.Group, arrays: list[NewArray]) -> list[Any]:
    """Create zarr arrays with their attributes, concurrently; returns them (async arrays) in order."""

    async def create(a: NewArray) -> Any:
        return await root._async_group.create_array(
            a.path, shape=a.data.shape, dtype=a.data.dtype, chunks=tuple(max(1, int(c)) for c in a.chunks),
            compressors=_ZARR_COMPRESSORS[a.kind], fill_value=0, config={"write_empty_chunks": True},
            attributes=a.attributes,
        )

    return _gather_all([create(a) for a in arrays])


def fill_arrays(targets: list[Any], arrays: list[NewArray]) -> None:
    """Write each array's data into the async zarr array :func:`create_arrays` made for it, concurrently."""
    _gather_all([target.setitem(Ellipsis, a.data) for target, a in zip(targets, arrays) if a.data.size])


def _gather_all(coroutines: list) -> list:
    """Run coroutines concurrently on zarr's event loop; the first failure is raised once all have ended
    (none is left writing into a store its caller then removes)."""

    async def every() -> list:
        return await asyncio.gather(*coroutines, return_exceptions=True)

    results = sync(every())
    for result in results:
        if isinstance(result, BaseException):
            raise result
    return results


def _raw_local_chunk_path(array: Any):
    """``frame -> chunk file path`` for a zarr array in a local directory stored one raw, native-endian
    frame per chunk (its chunk files then hold exactly the frame's bytes); None for any other array."""
    if not isinstance(array, zarr.Array) or not isinstance(array.store, zarr.storage.LocalStore):
        return None
    shape = tuple(array.shape)
    codecs = array.metadata.codecs
    if not shape or tuple(array.chunks) != (1, *shape[1:]) or len(codecs) != 1 or type(codecs[0]).__name__ != "BytesCodec":
        return None
    itemsize = np.dtype(array.dtype).itemsize
    endian = codecs[0].endian
    if itemsize > 1 and (endian is None or endian.value != sys.byteorder):
        return None
    base = pathlib.Path(array.store.root) / array.path
    zeros = (0,) * (len(shape) - 1)
    return lambda frame: base / array.metadata.encode_chunk_key((frame, *zeros))


def write_raw_frame(path: pathlib.Path, frame: np.ndarray, made_dirs: set[pathlib.Path]) -> None:
    """Write one frame's bytes (C order, native endianness) as the chunk file ``path``.

    ``made_dirs``: folders known to exist, kept up to date here; a chunk key's folders (``c/<frame>/0``
    …) are then made with one ``mkdir`` each instead of a walk up from the leaf, which fails first
    (directory operations are a good part of writing a frame on some file systems).
    """
    _write_file(path, memoryview(np.ascontiguousarray(frame)).cast("B"), made_dirs)


def write_rows(array: Any, first_row: int, rows: np.ndarray, made_dirs: set[pathlib.Path]) -> None:
    """Write ``rows`` as rows ``first_row:`` of ``array`` (already that long).

    Rows of a zarr array in a local directory that start on a chunk boundary and fill their last chunk,
    or end the array, have their chunk files written directly: zarr's bytes
    (:func:`zarr_files.chunk_files`), the folders made once (``made_dirs``, kept up to date), without
    zarr's event loop. Anything else (other rows, other arrays, codecs that module does not make) is
    written by the backend.
    """
    made = None
    if isinstance(array, zarr.Array) and isinstance(array.store, zarr.storage.LocalStore):
        stop = first_row + rows.shape[0]
        # A chunk is written whole: its padding must be no one's rows.
        if stop % array.chunks[0] == 0 or stop == array.shape[0]:
            made = zarr_files.chunk_files(rows, tuple(array.chunks), array.metadata.to_dict(), first_row)
    if made is None:
        array[first_row : first_row + rows.shape[0]] = rows
        return
    base = pathlib.Path(array.store.root) / array.path
    made_dirs.add(base)  # its metadata is there
    for key, value in made.items():
        _write_file(base / key, value, made_dirs)


def _make_dirs(folder: pathlib.Path, made: set[pathlib.Path]) -> None:
    """Make ``folder`` and the folders above it not in ``made`` (top down), adding them to ``made``."""
    missing = []
    while folder not in made and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    for folder in reversed(missing):
        try:
            os.mkdir(folder)
        except FileExistsError:
            if not folder.is_dir():
                raise
        made.add(folder)


class FrameAppender:
    """Appends frames to an array stored one frame per chunk, growing its first axis.

    For a raw zarr array in a local directory each frame is written straight to its chunk file (whose
    bytes are the frame's, as zarr would write them) and the shape is set once, by :meth:`finish`: zarr
    would rewrite the array's metadata for every frame (a resize) and hand each chunk through its event
    loop, most of an import's writing time. Other arrays (HDF5, compressed, remote) go through the backend.
    """

    def __init__(self, array: Any) -> None:
        self.array = array
        self.rows = int(array.shape[0])
        self._chunk_path = _raw_local_chunk_path(array)
        # The array's own folder exists (its metadata is in it).
        self._made_dirs = {pathlib.Path(array.store.root) / array.path} if self._chunk_path else set()

    def append(self, frame: np.ndarray) -> None:
        if self._chunk_path is None:
            self.array.resize((self.rows + 1, *frame.shape))
            self.array[self.rows] = frame
        else:
            write_raw_frame(self._chunk_path(self.rows), frame, self._made_dirs)
        self.rows += 1

    def finish(self) -> None:
        """Give the array its final number of frames (a no-op when it has it already)."""
        if int(self.array.shape[0]) != self.rows:
            self.array.resize((self.rows, *tuple(self.array.shape)[1:]))


def chunk_shape(array: Any) -> tuple[int, ...] | None:
    return tuple(array.chunks) if array.chunks is not None else None


def fill_value(array: Any) -> Any:
    """The value a chunk that is not stored reads as (Zarr v3 ``fill_value``, HDF5 fill value)."""
    if isinstance(array, zarr.Array):
        return array.fill_value
    return array.fillvalue


def missing_chunks(array: Any) -> list[tuple[int, ...]]:
    """Grid coordinates (C order) of the chunks of ``array`` absent from the store.

    One listing of the store (or of the HDF5 chunk index), not one probe per chunk.
    The caller bounds the number of chunks (corrupt metadata can claim any shape).
    """
    shape = tuple(array.shape)
    if not shape or 0 in shape:
        return []
    chunks = chunk_shape(array)
    if isinstance(array, zarr.Array):
        prefix = array.store_path.path
        base = f"{prefix}/" if prefix else ""
        keys = set(sync(_list_prefix(array.store_path.store, base)))
        grid = tuple(-(-n // c) for n, c in zip(shape, chunks))
        return [c for c in np.ndindex(*grid) if base + array.metadata.encode_chunk_key(c) not in keys]
    if chunks is None:
        return []  # contiguous storage: the data block exists with the dataset
    grid = tuple(-(-n // c) for n, c in zip(shape, chunks))
    if array.id.get_num_chunks() == int(np.prod(grid)):
        return []  # the common case, without a lookup per chunk (slow in HDF5's v1 B-trees)
    stored = set()

    def note(info: Any) -> None:
        stored.add(tuple(int(o) // int(c) for o, c in zip(info.chunk_offset, chunks)))

    if hasattr(array.id, "chunk_iter"):  # one pass over the index (HDF5 >= 1.14)
        array.id.chunk_iter(note)
    else:
        for i in range(array.id.get_num_chunks()):
            note(array.id.get_chunk_info(i))
    return [c for c in np.ndindex(*grid) if c not in stored]


async def _list_prefix(store: Any, prefix: str) -> list[str]:
    return [key async for key in store.list_prefix(prefix)]


def chunk_stored(array: Any, coords: tuple[int, ...]) -> bool:
    """Whether the chunk at grid coordinates ``coords`` is present in the store."""
    if isinstance(array, zarr.Array):
        key = array.metadata.encode_chunk_key(coords)
        if isinstance(array.store, zarr.storage.LocalStore):
            return os.path.isfile(os.path.join(str(array.store.root), array.path, key))
        path = f"{array.path}/{key}" if array.path else key
        return bool(sync(array.store.exists(path)))
    if array.chunks is None:
        return True  # contiguous storage: the data block exists with the dataset
    offset = tuple(int(i) * int(c) for i, c in zip(coords, array.chunks))
    return array.id.get_chunk_info_by_coord(offset).byte_offset is not None


def merge_attrs(root: Any, path: str, attrs: dict[str, Any]) -> None:
    """Add ``attrs`` to the attributes of the node at ``path`` below ``root`` (``""``: ``root``), making a
    group there where there is no node (objects and lists become JSON strings in HDF5).

    In a local zarr store an existing node's ``zarr.json`` is merged and rewritten directly, serialised as
    zarr serialises it, instead of through zarr's event loop (~1 ms a call, a dozen calls a scene); it is
    rewritten in place, for stores still being written (a scene writer's temporary store). zarr objects
    already open on that node keep their old attributes: for writers that do not use them again.
    """
    if is_local_zarr(root):
        metadata = pathlib.Path(root.store.root) / root.store_path.path / path / "zarr.json"
        try:
            document = json.loads(metadata.read_bytes())
        except FileNotFoundError:
            document = None
        if isinstance(document, dict) and isinstance(document.get("attributes", {}), dict):
            document["attributes"] = {**document.get("attributes", {}), **attrs}
            _write_file(metadata, json.dumps(document, allow_nan=True, indent=zarr.config.get("json_indent")).encode())
            return
    if not path:
        write_attrs(root, attrs)
    else:
        write_attrs(root[path] if path in root else root.require_group(path), attrs)


def read_attrs(node: Any) -> dict[str, Any]:
    """Attributes as plain JSON values (HDF5 JSON strings of objects decoded)."""
    out: dict[str, Any] = {}
    for key, value in node.attrs.items():
        if isinstance(node, (h5py.Group, h5py.Dataset)):
            value = _decode_hdf5_attr(value)
        out[key] = value
    return out


def _decode_hdf5_attr(value: Any) -> Any:
    if isinstance(value, bytes):
        value = value.decode("utf-8")
    if isinstance(value, str):
        stripped = value.lstrip()
        if stripped[:1] in ("{", "["):
            try:
                return json.loads(value)
            except json.JSONDecodeError:
                return value
        return value
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def write_attrs(node: Any, attrs: dict[str, Any]) -> None:
    """Write attributes; objects and lists become JSON strings in HDF5 (format v1)."""
    if isinstance(node, (zarr.Array, zarr.Group)):
        node.update_attributes(attrs)  # one metadata write for them all (one per key through ``attrs``)
        return
    for key, value in attrs.items():
        if isinstance(value, (dict, list, tuple)):
            value = json.dumps(value)
        node.attrs[key] = value


class DirectFrameReader:
    """Reads whole uncompressed frame chunks of a local store straight from the file.

    zarr-python and h5py add per-call overhead (event loop, buffer copies) that
    costs 40–75 % of the throughput of reading a 4 MiB radar cube chunk into
    numpy (measured in ``benchmarks/bench_format.py``); for arrays stored one raw
    frame per chunk on a local disk, the chunk's bytes are the frame, so we read
    them into the output array ourselves.  Anything else uses the backend.
    """

    def __init__(self, frame_shape: tuple[int, ...], dtype: np.dtype, locate, missing_fill: Any = None) -> None:
        self.frame_shape = frame_shape
        self.dtype = dtype
        self.frame_bytes = int(np.prod(frame_shape, dtype=np.int64)) * dtype.itemsize
        self._locate = locate  # frame -> (file path, byte offset, stored size), or None when not stored
        # None: a chunk that is not stored is an error; otherwise the value it reads as.
        self._missing_fill = missing_fill

    def read(self, start: int, stop: int) -> np.ndarray:
        """Frames ``start:stop`` as one array; raises ValueError for a missing or wrong-size chunk."""
        out = np.empty((stop - start, *self.frame_shape), dtype=self.dtype)
        self.read_into(start, stop, out)
        return out

    def read_into(self, start: int, stop: int, out: np.ndarray) -> None:
        """Read frames ``start:stop`` into ``out`` (C-contiguous, this reader's dtype and frame shape)."""
        flat = out.reshape(stop - start, -1).view(np.uint8)
        for row, frame in enumerate(range(start, stop)):
            located = self._locate(frame)
            if located is None:
                if self._missing_fill is None:
                    raise ValueError(f"chunk of frame {frame} is missing")
                out[row] = self._missing_fill
                continue
            path, offset, size = located
            if size != self.frame_bytes:
                raise ValueError(f"chunk of frame {frame} holds {size} bytes, expected {self.frame_bytes}")
            with open(path, "rb", buffering=0) as handle:
                handle.seek(offset)
                got = handle.readinto(flat[row])
            if got != self.frame_bytes:
                raise ValueError(f"chunk of frame {frame} is truncated: read {got} of {self.frame_bytes} bytes")


def direct_frame_reader(array: Any, missing_is_fill: bool = False) -> DirectFrameReader | None:
    """A :class:`DirectFrameReader` for ``array`` when it is local, raw and one frame per chunk, else None.

    ``missing_is_fill``: a chunk that is not stored reads as the array's fill value
    (Zarr v3 semantics, for stores without checksums); otherwise it is an error.
    """
    shape = tuple(array.shape)
    if not shape or tuple(array.chunks or ()) != (1, *shape[1:]):
        return None
    dtype = np.dtype(array.dtype)
    if not dtype.isnative and dtype.itemsize > 1:
        return None
    if isinstance(array, zarr.Array):
        chunk_path = _raw_local_chunk_path(array)
        if chunk_path is None:
            return None

        def locate_zarr(frame: int) -> tuple[str, int, int] | None:
            path = chunk_path(frame)
            try:
                return str(path), 0, path.stat().st_size
            except FileNotFoundError:
                return None

        return DirectFrameReader(shape[1:], dtype, locate_zarr, fill_value(array) if missing_is_fill else None)
    if isinstance(array, h5py.Dataset):
        if array.compression or array.shuffle or array.fletcher32 or array.scaleoffset is not None:
            return None
        if array.file.driver != "sec2" or not os.path.isfile(array.file.filename):
            return None
        filename = array.file.filename
        zeros = (0,) * (len(shape) - 1)
        chunk_id = array.id
        located: dict[int, tuple[str, int, int]] = {}  # the B-tree lookup costs as much as the read

        def locate_hdf5(frame: int) -> tuple[str, int, int] | None:
            if frame not in located:
                info = chunk_id.get_chunk_info_by_coord((frame, *zeros))
                if info.byte_offset is None:
                    return None
                located[frame] = (filename, int(info.byte_offset), int(info.size))
            return located[frame]

        return DirectFrameReader(shape[1:], dtype, locate_hdf5, fill_value(array) if missing_is_fill else None)
    return None


def consolidated_mismatches(location: str | os.PathLike, storage_options: dict | None = None) -> list[str] | None:
    """Paths whose consolidated metadata differs from the store (None without consolidated metadata)."""
    if backend_from_path(location) != "zarr":
        return None
    try:
        consolidated = open_store(location, storage_options, consolidated=True)
    except ValueError:
        return None  # no consolidated metadata
    actual = open_store(location, storage_options, consolidated=False)

    def summary(root: Any) -> dict[str, tuple]:
        return {
            path: (tuple(node.shape), str(node.dtype)) if is_array(node) else ("group",)
            for path, node in walk(root)
        }

    try:
        want, have = summary(actual.root), summary(consolidated.root)
    except MetadataError:
        return None  # unreadable metadata is reported by the metadata checks
    finally:
        consolidated.close()
        actual.close()
    return sorted(path for path in set(want) | set(have) if want.get(path) != have.get(path))
