"""The files zarr writes for a whole array (its ``zarr.json`` and every chunk), made directly.

zarr makes them through its event loop, ~0.9 ms an array of Python (dtype parsing, parent groups' metadata
made anew for every array, each chunk's codec call handed to a worker thread): 36 ms for 40 small arrays
of 3 000–9 000 rows against 10 ms here, and an import of the benchmark's recording 0.42–0.47 s against
0.35–0.36 s with the lidar's chunks made here too (``python benchmarks/bench_release.py --variants``,
docs/release.md).

The metadata is zarr's own: a document zarr made for an array of the same data type, rank and codecs
(the *template*), with the three fields the zarr v3 specification gives each array — ``shape``, the
regular chunk grid's ``chunk_shape`` and ``attributes`` — set, and serialised as zarr serialises it. The
chunks are encoded by the numcodecs codecs zarr itself calls, configured from the template's ``codecs``;
a template with any other codec chain is refused (None), and the caller lets zarr write the array.
``tests/format/test_staged_arrays.py`` compares the files with zarr's, byte for byte.
"""

from __future__ import annotations

import json
from typing import Any

import numcodecs
import numpy as np
import zarr

_SHUFFLES = {"noshuffle": 0, "shuffle": 1, "bitshuffle": 2}


def chunk_codec(template: dict[str, Any]) -> tuple[str | None, Any] | None:
    """``(endian, compressor or None)`` of a template's codecs (``bytes`` then at most one of ``zstd`` and
    ``blosc``); None for any other chain."""
    codecs = template.get("codecs", [])
    if not codecs or codecs[0].get("name") != "bytes" or len(codecs) > 2:
        return None
    endian = codecs[0].get("configuration", {}).get("endian")
    if len(codecs) == 1:
        return endian, None
    name, config = codecs[1].get("name"), codecs[1].get("configuration", {})
    try:
        if name == "zstd":
            return endian, numcodecs.Zstd(level=config["level"], checksum=config.get("checksum", False))
        if name == "blosc":
            return endian, numcodecs.Blosc(
                cname=config["cname"], clevel=config["clevel"], shuffle=_SHUFFLES[config["shuffle"]],
                blocksize=config.get("blocksize", 0), typesize=config["typesize"],
            )
    except (KeyError, TypeError):  # a configuration this numcodecs does not take: zarr writes the array
        return None
    return None


def array_files(
    path: str, data: np.ndarray, chunks: tuple[int, ...], attributes: dict[str, Any], template: dict[str, Any]
) -> dict[str, bytes] | None:
    """The files of array ``path`` holding ``data`` in ``chunks`` (keys relative to the store): its
    ``zarr.json`` and :func:`chunk_files`; None when the template's codecs are not ones made here."""
    made = chunk_files(data, chunks, template)
    if made is None:
        return None
    document = dict(template)
    document["shape"] = list(data.shape)
    grid = dict(template["chunk_grid"])
    grid["configuration"] = {**grid.get("configuration", {}), "chunk_shape": list(chunks)}
    document["chunk_grid"] = grid
    document["attributes"] = attributes
    files = {f"{path}/zarr.json": json.dumps(document, allow_nan=True, indent=zarr.config.get("json_indent")).encode()}
    files.update((f"{path}/{key}", value) for key, value in made.items())
    return files


def chunk_files(
    data: np.ndarray, chunks: tuple[int, ...], template: dict[str, Any], first_row: int = 0
) -> dict[str, bytes] | None:
    """The encoded chunks holding ``data`` as rows ``first_row:`` of an array (``first_row`` a multiple of
    ``chunks[0]``), keyed as zarr's default chunk keys (``c/<i>/<j>…`` with the template's separator);
    None when the template's codecs, chunk grid or fill value are not ones made here.

    Every chunk is stored (zarr's ``write_empty_chunks``), a last one short of rows padded to the whole
    chunk shape with the fill value, as zarr stores it.
    """
    codec = chunk_codec(template)
    if codec is None or data.ndim == 0 or first_row % chunks[0]:
        return None
    endian, compressor = codec
    try:
        fill = np.asarray(template.get("fill_value", 0)).astype(data.dtype)
    except (TypeError, ValueError):
        return None
    if fill.ndim:  # a complex fill value's [real, imaginary]: zarr writes the array
        return None
    encoding = template.get("chunk_key_encoding", {})
    if encoding.get("name") != "default" or template.get("chunk_grid", {}).get("name") != "regular":
        return None
    separator = encoding.get("configuration", {}).get("separator", "/")
    stored = data.dtype if data.dtype.itemsize == 1 else data.dtype.newbyteorder("<" if endian == "little" else ">")
    first_chunk = first_row // chunks[0]
    files = {}
    for index in np.ndindex(*(-(-n // c) for n, c in zip(data.shape, chunks))):
        block = data[tuple(slice(i * c, (i + 1) * c) for i, c in zip(index, chunks))]
        if block.shape != chunks:
            whole = np.full(chunks, fill, data.dtype)
            whole[tuple(slice(0, n) for n in block.shape)] = block
            block = whole
        raw = np.ascontiguousarray(block, stored).reshape(-1).view(np.uint8)
        key = separator.join(["c", str(first_chunk + index[0]), *map(str, index[1:])])
        files[key] = bytes(compressor.encode(raw)) if compressor else raw.tobytes()
    return files
