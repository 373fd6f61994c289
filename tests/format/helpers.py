"""Direct backend access for tests: read every array and attribute, and break stores on purpose.

Kept independent of zendar_dataset.format.stores so the tests do not check the code with itself.
"""

from __future__ import annotations

import json
import pathlib
import warnings

import google_crc32c
import h5py
import numpy as np
import zarr


def open_raw(path: pathlib.Path, mode: str = "r"):
    path = pathlib.Path(path)
    if path.suffix == ".zarr":
        return zarr.open_group(str(path), mode=mode)
    return h5py.File(path, mode)


def _attrs(node) -> dict:
    out = {}
    for key, value in node.attrs.items():
        if isinstance(node, (h5py.Group, h5py.Dataset)):
            if isinstance(value, bytes):
                value = value.decode()
            if isinstance(value, str) and value[:1] in "{[":
                value = json.loads(value)
            elif isinstance(value, np.generic):
                value = value.item()
        out[key] = value
    return out


def dump(path: pathlib.Path) -> tuple[dict[str, np.ndarray], dict[str, dict]]:
    """Every array (read in full) and every group/array's attributes, keyed by path ('' = root)."""
    arrays, attrs = {}, {}
    root = open_raw(path)

    def visit(group, prefix):
        attrs[prefix] = _attrs(group)
        for name in sorted(group.keys()):
            node = group[name]
            full = f"{prefix}/{name}" if prefix else name
            if isinstance(node, (zarr.Group, h5py.Group)):
                visit(node, full)
            else:
                arrays[full] = np.asarray(node[...])
                attrs[full] = _attrs(node)

    try:
        visit(root, "")
    finally:
        if isinstance(root, h5py.File):
            root.close()
    return arrays, attrs


def reconsolidate(path: pathlib.Path) -> None:
    """Refresh zarr consolidated metadata after an edit, as a careful tool would."""
    if pathlib.Path(path).suffix == ".zarr":
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            zarr.consolidate_metadata(str(path))


def crc32c_hex(data: np.ndarray, rows_per_chunk: int) -> str:
    """The chunk_crc32c attribute of ``data`` chunked ``rows_per_chunk`` rows at a time (whole other axes)."""
    data = np.ascontiguousarray(data, dtype=data.dtype.newbyteorder("<"))
    return "".join(
        f"{google_crc32c.value(data[start : start + rows_per_chunk].tobytes()):08x}"
        for start in range(0, data.shape[0], rows_per_chunk)
    )


def chunk_rows(path: pathlib.Path, array_path: str) -> int:
    """Rows per chunk of an array (the writer chunks along the first axis only)."""
    root = open_raw(path)
    try:
        return int(root[array_path].chunks[0])
    finally:
        if isinstance(root, h5py.File):
            root.close()


def replace_array(path: pathlib.Path, array_path: str, data: np.ndarray | None) -> None:
    """Delete an array and (unless data is None) write ``data`` in its place, with its chunk checksums,
    as a careful tool would: frame arrays (``cube``, ``image``) one row per chunk, others in one chunk."""
    root = open_raw(path, "r+" if pathlib.Path(path).suffix == ".h5" else "a")
    try:
        del root[array_path]
        if data is not None:
            rows = 1 if array_path.rsplit("/", 1)[-1] in ("cube", "image") else max(1, data.shape[0])
            chunks = (rows, *data.shape[1:])
            if isinstance(root, h5py.File):
                node = root.create_dataset(array_path, data=data, chunks=chunks)
            else:
                node = root.create_array(array_path, shape=data.shape, dtype=data.dtype, chunks=chunks)
                node[...] = data
            node.attrs["chunk_crc32c"] = crc32c_hex(data, rows)
    finally:
        if isinstance(root, h5py.File):
            root.close()
    reconsolidate(path)


def set_attr(path: pathlib.Path, node_path: str, key: str, value) -> None:
    root = open_raw(path, "r+" if pathlib.Path(path).suffix == ".h5" else "a")
    try:
        node = root[node_path] if node_path else root
        if value is None:
            del node.attrs[key]
        else:
            node.attrs[key] = value
    finally:
        if isinstance(root, h5py.File):
            root.close()
    reconsolidate(path)


def corrupt_chunk(path: pathlib.Path, array_path: str, frame: int) -> None:
    """Make one frame's chunk undecodable: truncate the chunk file (zarr) or scramble it (HDF5, compressed arrays)."""
    path = pathlib.Path(path)
    if path.suffix == ".zarr":
        array = zarr.open_array(str(path / array_path), mode="r")
        key = "/".join(["c", str(frame)] + ["0"] * (array.ndim - 1))
        chunk = path / array_path / key
        chunk.write_bytes(chunk.read_bytes()[:7])
        return
    with h5py.File(path, "r") as handle:
        dataset = handle[array_path]
        assert dataset.compression is not None, "only compressed HDF5 chunks can be detected as corrupt"
        info = dataset.id.get_chunk_info_by_coord((frame,) + (0,) * (dataset.ndim - 1))
    with open(path, "r+b") as raw:
        raw.seek(info.byte_offset)
        raw.write(b"\xff" * info.size)
