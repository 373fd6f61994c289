"""Content hashes that tie a baseline's stored result to what it was made from.

A dataset is identified by the SHA-256 of its ``dataset.json`` bytes: the file lists every scene and
the train / val / test splits, so two roots with the same fingerprint split the same scenes the same
way (the scene stores themselves carry their own chunk checksums). Small JSON records are hashed in
canonical form (sorted keys, no whitespace) so that reformatting a file does not change its hash.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import socket
import weakref
from typing import Any

import fsspec

from zendar_dataset.errors import ZendarError, ZendarFormatError
from zendar_dataset.format import stores
from zendar_dataset.format.reader import DatasetIndex, open_dataset
from zendar_dataset.format.schema import DATASET_JSON

SHA256_HEX = re.compile(r"[0-9a-f]{64}")
# An opened dataset is hashed once: a run passes one DatasetIndex to every step.
_FINGERPRINTS: weakref.WeakKeyDictionary[DatasetIndex, str] = weakref.WeakKeyDictionary()


def dataset_index(dataset: DatasetIndex | str | os.PathLike) -> DatasetIndex:
    """``dataset`` itself when already opened, else :func:`~zendar_dataset.format.reader.open_dataset` of it."""
    return dataset if isinstance(dataset, DatasetIndex) else open_dataset(dataset)


def dataset_on_worker(root: str, storage_options: dict, scene_id: str) -> DatasetIndex:
    """The dataset at ``root`` opened by a task of ``scene_id`` on a worker process or a Dask worker.

    Raises
    ------
    ZendarError
        When this host cannot read it, naming the host: every worker must see it at the same path or URL.
    """
    try:
        return open_dataset(root, storage_options)
    except (OSError, ZendarError) as exc:
        raise ZendarError(f"{scene_id}: the dataset {root} cannot be read on host {socket.gethostname()} "
                          f"({exc}); every worker must see it at the same path or URL") from None


def task_root(index: DatasetIndex) -> str:
    """``index``'s root as a task sends it to another host: a URL, or an absolute path (the other host
    has another working directory)."""
    return str(index.root) if stores.is_url(index.root) else os.path.abspath(index.root)


def dataset_location(dataset: DatasetIndex | str | os.PathLike) -> str | os.PathLike:
    """The root of ``dataset`` as given: an opened dataset's ``root``, else ``dataset`` itself."""
    return dataset.root if isinstance(dataset, DatasetIndex) else dataset


def dataset_fingerprint(dataset: DatasetIndex | str | os.PathLike) -> str:
    """Hex SHA-256 of the bytes of a dataset's ``dataset.json``.

    Parameters
    ----------
    dataset
        A dataset opened with :func:`zendar_dataset.format.reader.open_dataset` (hashed once per
        opened dataset), or its root (local path or fsspec URL), which is opened (and its
        ``dataset.json`` checked) first.

    Raises
    ------
    ZendarFormatError
        When ``dataset.json`` is missing or violates the schema (all problems listed), or vanished
        since the dataset was opened.
    """
    dataset = dataset_index(dataset)
    if dataset not in _FINGERPRINTS:
        _FINGERPRINTS[dataset] = _sha256_of_dataset_json(dataset)
    return _FINGERPRINTS[dataset]


def _sha256_of_dataset_json(dataset: DatasetIndex) -> str:
    location = stores.join_location(dataset.root, DATASET_JSON)
    try:
        if stores.is_url(location):
            with fsspec.open(location, "rb", **dataset.storage_options) as handle:
                data = handle.read()
        else:
            with open(stores.local_path(location), "rb") as handle:
                data = handle.read()
    except (FileNotFoundError, NotADirectoryError, IsADirectoryError):
        raise ZendarFormatError(f"{location}: expected the dataset's {DATASET_JSON}, found none") from None
    return hashlib.sha256(data).hexdigest()


def canonical_json_bytes(content: Any) -> bytes:
    """``content`` as canonical JSON: sorted keys, no whitespace, ASCII only, no NaN."""
    return json.dumps(content, sort_keys=True, separators=(",", ":"), allow_nan=False).encode("ascii")


def canonical_json_sha256(content: Any) -> str:
    """Hex SHA-256 of :func:`canonical_json_bytes`."""
    return hashlib.sha256(canonical_json_bytes(content)).hexdigest()


__all__ = ["SHA256_HEX", "canonical_json_bytes", "canonical_json_sha256", "dataset_fingerprint"]
