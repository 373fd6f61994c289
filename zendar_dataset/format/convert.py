"""Lossless conversion of a dataset between the zarr and HDF5 backends.

Every array is copied bit for bit with the same chunk shape, every attribute
with an equal value; only the container and its compressors change.  Chunk
checksums (docs/format.md) are recomputed from the values copied and, where
the source records them, must match: a corrupt source is refused, not
carried over.  Every converted store records checksums.  The
output is written under a temporary sibling and renamed into place, and an
existing non-empty output is never touched.
"""

from __future__ import annotations

import os
import pathlib
from typing import Any

import numpy as np

from zendar_dataset import temporary_files as temporary
from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.format import checksums, stores
from zendar_dataset.format.reader import open_dataset
from zendar_dataset.format.schema import BACKEND_SUFFIX, DATASET_JSON
from zendar_dataset.atomic_files import write_json_atomic
from zendar_dataset.output_location import refuse_output_inside

_TO = {"zarr": "zarr", "hdf5": "hdf5", "h5": "hdf5"}
# Rows copied per read for arrays not stored one frame per chunk (bounds memory).
_COPY_BLOCK_BYTES = 64 * 2**20


def _copy_array(source: Any, target_root: Any, path: str, scene: str, verify: bool) -> None:
    """Copy one array chunk-aligned block by block, recomputing its chunk checksums.

    With ``verify`` (the source records checksums) each recomputed checksum must
    equal the recorded one; a mismatch raises ZendarFormatError naming the chunk.
    """
    shape = tuple(source.shape)
    chunks = stores.chunk_shape(source) or shape or (1,)
    target = stores.create_array(
        target_root,
        path,
        shape=shape,
        dtype=np.dtype(source.dtype),
        chunks=chunks,
        kind=stores.array_kind(path),
        resizable=len(shape) > 0,
    )
    attrs = stores.read_attrs(source)
    expected = None
    if verify:
        try:
            expected = checksums.decode(attrs.get(checksums.ARRAY_ATTR), checksums.chunk_count(shape, chunks))
        except ValueError as exc:
            raise ZendarFormatError(f"{scene}: {path}: {checksums.ARRAY_ATTR}: {exc}") from None
    grid = checksums.grid_shape(shape, chunks)
    computed: list[int] = []
    if not shape:
        value = _read_rows(source, None, chunks, scene, path)
        target[...] = value
        computed = checksums.block_checksums(value, chunks)
    elif source.size:
        row_bytes = max(1, int(np.prod(shape[1:], dtype=np.int64)) * np.dtype(source.dtype).itemsize)
        step = max(chunks[0], (_COPY_BLOCK_BYTES // row_bytes) // chunks[0] * chunks[0])
        for start in range(0, shape[0], step):
            block = _read_rows(source, slice(start, start + step), chunks, scene, path)
            target[start : start + step] = block
            for coords, index, found in checksums.array_chunk_checksums(block, start, chunks, grid):
                computed.append(found)
                if expected is not None and computed[-1] != expected[index]:
                    raise ZendarFormatError(
                        f"{scene}: {path}: chunk {list(coords)}: expected {checksums.ALGORITHM} "
                        f"{expected[index]:08x} (recorded), found {computed[-1]:08x}; the source is corrupt"
                    )
    attrs[checksums.ARRAY_ATTR] = checksums.encode(computed)
    stores.write_attrs(target, attrs)


def _read_rows(source: Any, rows: slice | None, chunks: tuple[int, ...], scene: str, path: str) -> np.ndarray:
    """``source[rows]`` (``source[...]`` for ``None``), its chunk-aligned rows read whole.

    Raises
    ------
    ZendarFormatError
        When stored bytes do not decode, naming the scene, the array and the first unreadable
        chunk row, as ``zendar-data validate`` does.
    """
    try:
        return np.asarray(source[...] if rows is None else source[rows])
    except stores.DECODE_ERRORS as exc:
        cause = exc
    if rows is None:
        where, span = [], ""
    else:
        # A block spans several chunk rows: read them one by one to name the one that fails.
        where, span = _first_unreadable_row(source, rows, chunks)
    raise ZendarFormatError(
        f"{scene}: {path}: chunk {where}: expected a readable chunk{span}, found a truncated or corrupt one "
        f"({type(cause).__name__}: {cause}); the source is corrupt"
    ) from None


def _first_unreadable_row(source: Any, rows: slice, chunks: tuple[int, ...]) -> tuple[list, str]:
    """Chunk coordinates (``*`` for an axis of several chunks) and row span of the first chunk row of
    ``rows`` that does not decode; the whole block when each row alone reads (a flaky read)."""
    grid = checksums.grid_shape(tuple(source.shape), chunks)
    stop = min(rows.stop, source.shape[0])
    for start in range(rows.start, stop, chunks[0]):
        try:
            source[start : start + chunks[0]]
        except stores.DECODE_ERRORS:
            where = [start // chunks[0], *(0 if g == 1 else "*" for g in grid[1:])]
            return where, f" (rows {start}:{min(start + chunks[0], stop)})"
    first, last = rows.start // chunks[0], (stop - 1) // chunks[0]
    return [f"{first}..{last}", *(0 if g == 1 else "*" for g in grid[1:])], f" (rows {rows.start}:{stop})"


def convert_scene(source_root: Any, target_path: pathlib.Path, backend: str, scene: str = "") -> None:
    """Copy one open scene's hierarchy (groups, arrays, attributes) into a new store.

    Chunk checksums are recomputed; where the source records them they are checked too.
    """
    scene = scene or str(target_path)
    target = stores.create_store(target_path, backend)
    try:
        root_attrs = stores.read_attrs(source_root)
        verify = root_attrs.get(checksums.ROOT_ATTR) == checksums.ALGORITHM
        stores.write_attrs(target.root, {**root_attrs, checksums.ROOT_ATTR: checksums.ALGORITHM})
        try:
            nodes = stores.walk(source_root)
        except stores.MetadataError as exc:
            raise ZendarFormatError(f"{scene}: {exc}") from None
        for path, node in nodes:
            if stores.is_group(node):
                stores.write_attrs(target.root.require_group(path), stores.read_attrs(node))
            else:
                _copy_array(node, target.root, path, scene, verify)
                target.raise_if_failed()  # disk full: stop now, not after copying the rest into the void
    finally:
        target.close()
    if backend == "zarr":
        stores.consolidate(target_path)


def convert_dataset(
    root: str | os.PathLike, out: str | os.PathLike, to: str = "zarr", storage_options: dict | None = None
) -> pathlib.Path:
    """Convert every scene of ``root`` into backend ``to`` under the new root ``out``.

    Parameters
    ----------
    root
        Source dataset (local path or fsspec URL); only read.
    out
        New local dataset root; must not exist or be an empty directory.
    to : {"zarr", "hdf5"}

    Returns
    -------
    pathlib.Path
        ``out``.
    """
    if to not in _TO:
        raise ValueError(f"to: expected 'zarr' or 'hdf5', found {to!r}")
    backend = _TO[to]
    out = pathlib.Path(out)
    refuse_output_inside(out, datasets=(root,), what="OUT")
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise FileExistsError(f"{out}: output exists and is not an empty directory; choose a new path")
    index = open_dataset(root, storage_options)
    out.parent.mkdir(parents=True, exist_ok=True)
    temporary.remove_stale_temporaries(out.parent, out.name)  # left by a killed conversion
    temp = temporary.temporary_sibling(out)
    (temp / "scenes").mkdir(parents=True)
    try:
        scenes = {}
        for scene_id in index.scene_ids():
            relative = f"scenes/{scene_id}{BACKEND_SUFFIX[backend]}"
            with index.open_scene(scene_id) as scene:  # checks the scene's metadata first
                convert_scene(scene.store_root, temp / relative, backend, scene_id)
            scenes[scene_id] = {"path": relative}
        document = {**index.document, "scenes": scenes}
        write_json_atomic(temp / DATASET_JSON, document)
        if out.exists():
            out.rmdir()  # empty, checked above
        os.replace(temp, out)
        temporary.forget(temp)
    except BaseException:
        temporary.remove_temporary(temp)
        raise
    return out
