"""Per-chunk checksums of format v1 (docs/format.md, "Chunk checksums").

A store that records checksums has the root attribute ``chunk_checksums =
"crc32c"``, and every array in it the attribute ``chunk_crc32c``: one CRC-32C
per chunk, in C order of the chunk grid, each as 8 lowercase hex digits,
concatenated into one string.  A chunk's checksum covers its *decoded* values
inside the array's bounds (an edge chunk's padding excluded), as C-ordered
little-endian bytes, so it does not depend on the backend or the compressor:
``convert`` carries checksums unchanged and can check them while copying.

CRC-32C rather than a cryptographic hash: the threat is bit rot and careless
edits, not an adversary, and google-crc32c (already a zarr dependency) runs at
memory speed with SSE4.2 (about 10 GB/s here), so recording a 4 MiB cube's
checksum costs well under a millisecond.  A CRC detects every error burst of
up to 32 bits, so any overwrite of 4 consecutive bytes.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from typing import Any

import google_crc32c
import numpy as np

ALGORITHM = "crc32c"
ROOT_ATTR = "chunk_checksums"
ARRAY_ATTR = "chunk_crc32c"
_HEX_DIGITS = 8
_HEX = re.compile(r"[0-9a-f]*")


def grid_shape(shape: tuple[int, ...], chunks: tuple[int, ...]) -> tuple[int, ...]:
    """Number of chunks along each axis (``ceil(shape / chunks)``); a 0-d array has one chunk."""
    return tuple(-(-int(n) // int(c)) for n, c in zip(shape, chunks))


def chunk_count(shape: tuple[int, ...], chunks: tuple[int, ...]) -> int:
    return math.prod(grid_shape(shape, chunks))


def crc32c(values: np.ndarray) -> int:
    """CRC-32C of an array's values as C-ordered little-endian bytes."""
    data = np.ascontiguousarray(values, dtype=values.dtype.newbyteorder("<")).view()
    data.flags.writeable = False  # google_crc32c accepts read-only buffers only
    return int(google_crc32c.value(data.reshape(-1).view(np.uint8)))


def iter_block_chunks(block: np.ndarray, chunks: tuple[int, ...]) -> Iterator[tuple[tuple[int, ...], np.ndarray]]:
    """(grid coordinates within the block, values) of each chunk of ``block``, in C order.

    ``block`` starts on a chunk boundary on every axis (rows ``k·chunks[0]`` onwards,
    every other axis whole), as the writer, the validator and convert read arrays.
    """
    if block.ndim == 0:
        yield (), block
        return
    for coords in np.ndindex(*grid_shape(block.shape, chunks)):
        yield coords, block[tuple(slice(i * c, (i + 1) * c) for i, c in zip(coords, chunks))]


def block_checksums(block: np.ndarray, chunks: tuple[int, ...]) -> list[int]:
    """CRC-32C of each chunk of a chunk-aligned ``block`` (see :func:`iter_block_chunks`), in C order."""
    return [crc32c(values) for _, values in iter_block_chunks(block, chunks)]


def encode(checksums: list[int]) -> str:
    """The ``chunk_crc32c`` attribute value: 8 hex digits per chunk."""
    return "".join(f"{value:08x}" for value in checksums)


def decode(text: Any, n_chunks: int) -> list[int]:
    """Checksums from a ``chunk_crc32c`` value; ValueError saying what is wrong with it."""
    if not isinstance(text, str) or not _HEX.fullmatch(text):
        shown = f"{text[:16]!r}..." if isinstance(text, str) else type(text).__name__
        raise ValueError(f"expected a string of lowercase hex digits, found {shown}")
    if len(text) != n_chunks * _HEX_DIGITS:
        raise ValueError(
            f"expected {n_chunks} checksums ({n_chunks * _HEX_DIGITS} hex digits, one per chunk), "
            f"found {len(text)} hex digits"
        )
    return [int(text[i : i + _HEX_DIGITS], 16) for i in range(0, len(text), _HEX_DIGITS)]


def linear_index(coords: tuple[int, ...], grid: tuple[int, ...]) -> int:
    """Position of chunk ``coords`` in C order of a chunk grid."""
    return int(np.ravel_multi_index(coords, grid)) if grid else 0


def array_chunk_checksums(
    block: np.ndarray, start_row: int, chunks: tuple[int, ...], grid: tuple[int, ...]
) -> Iterator[tuple[tuple[int, ...], int, int]]:
    """``(coordinates in the whole array's grid, linear index, CRC-32C)`` of each chunk of ``block``.

    ``block`` holds rows from ``start_row`` (a chunk boundary) with every other axis whole; the
    validator, the verifying reader and convert all compare these against the recorded list.
    """
    for coords, values in iter_block_chunks(block, chunks):
        if coords:
            coords = (coords[0] + start_row // chunks[0], *coords[1:])
        yield coords, linear_index(coords, grid), crc32c(values)
