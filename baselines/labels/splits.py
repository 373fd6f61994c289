"""The semi-supervised split: training scenes with manual labels, and training scenes without.

The paper pretrains on many automatic labels and fine-tunes on few manual ones (§4.1). To reproduce
that on a dataset whose every training scene is labelled, the training split is divided once, by a
seeded draw, into a *labelled* part, whose manual labels a model may see, and an *unlabelled* part,
seen only through automatic labels. Validation and test scenes are never in either part.

The split is written as a small versioned JSON file with a SHA-256 of its canonical content, so a
hand edit (moving a scene into the labelled part) is caught when the file is read back, and it
names the dataset (the SHA-256 of its ``dataset.json``) it was drawn from.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from zendar_dataset.errors import ZendarError
from zendar_dataset.atomic_files import prepare_out_dir, write_json_atomic
from zendar_dataset.format.reader import DatasetIndex
from zendar_dataset.output_location import refuse_output_inside

from zendar_baselines.fingerprints import SHA256_HEX, canonical_json_sha256, dataset_fingerprint, dataset_index, dataset_location

FORMAT_NAME = "zendar-semisupervised-split"
FORMAT_VERSION = 1
TRAIN_SPLIT = "train"
_OTHER_SPLITS = ("val", "test")


class SplitError(ZendarError):
    """A split cannot be made or read; ``problems`` lists every problem found."""


class ManualLabelLeakError(ZendarError):
    """Manual labels of an unlabelled scene were about to be used."""


@dataclass(frozen=True)
class SemiSupervisedSplit:
    """The training scenes divided into a labelled and an unlabelled part.

    Attributes
    ----------
    labelled : tuple of str
        Scene ids whose manual labels a model may see, in the dataset's training order.
    unlabelled : tuple of str
        Scene ids seen only through automatic labels, in the dataset's training order.
    labelled_fraction : float
        The share of training scenes asked for in the labelled part (the part holds
        ``round(fraction * n_train)`` scenes, at least 1 and at most ``n_train - 1``).
    seed : int
        Seed of the ``numpy.random.Generator`` permutation that drew the labelled part.
    dataset_fingerprint : str
        SHA-256 (hex) of the ``dataset.json`` bytes of the dataset split.
    """

    labelled: tuple[str, ...]
    unlabelled: tuple[str, ...]
    labelled_fraction: float
    seed: int
    dataset_fingerprint: str

    def to_json(self) -> dict[str, Any]:
        """The file's content without its ``sha256`` (what the checksum covers)."""
        return {
            "format": FORMAT_NAME,
            "format_version": FORMAT_VERSION,
            "labelled": list(self.labelled),
            "unlabelled": list(self.unlabelled),
            "labelled_fraction": self.labelled_fraction,
            "seed": self.seed,
            "dataset_fingerprint": self.dataset_fingerprint,
        }

    def check_manual_label_use(self, scene_ids: Iterable[str]) -> None:
        """Guard the promise that no model sees the manual labels of a scene it treats as unlabelled.

        Call it with the scenes whose manual labels are about to be read (for training targets,
        fine-tuning, or label-quality figures that feed a choice).

        Raises
        ------
        ManualLabelLeakError
            Naming every unlabelled scene among ``scene_ids``.
        """
        unlabelled = set(self.unlabelled)
        leaked = [scene_id for scene_id in dict.fromkeys(scene_ids) if scene_id in unlabelled]
        if leaked:
            raise ManualLabelLeakError(
                f"manual labels of {len(leaked)} scene(s) of the unlabelled part were about to be used: {leaked}; "
                "the semi-supervised split allows manual labels of the labelled part only"
            )


def _labelled_count(labelled_fraction: float, n_train: int) -> int:
    # Half up rather than Python's round-half-even, so 0.5 of 5 scenes gives 3 on every platform.
    return min(max(math.floor(labelled_fraction * n_train + 0.5), 1), n_train - 1)


def make_split(dataset_root: DatasetIndex | str | os.PathLike, labelled_fraction: float, seed: int) -> SemiSupervisedSplit:
    """Draw the labelled part of a dataset's training scenes.

    Parameters
    ----------
    dataset_root
        Dataset root (local path or fsspec URL), or the dataset already opened.
    labelled_fraction
        Share of training scenes to put in the labelled part, in (0, 1).
    seed
        Non-negative integer; the same seed and dataset give the same split.

    Raises
    ------
    SplitError
        When the fraction or seed is invalid, the training split has fewer than 2 scenes (each part
        needs one), or a training scene is also listed in ``val`` or ``test``.
    """
    problems = []
    if isinstance(labelled_fraction, bool) or not isinstance(labelled_fraction, int | float) or not 0.0 < labelled_fraction < 1.0:
        problems.append(f"labelled_fraction: expected a number in (0, 1), found {labelled_fraction!r}")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        problems.append(f"seed: expected an integer >= 0, found {seed!r}")
    dataset = dataset_index(dataset_root)
    train = dataset.scene_ids(TRAIN_SPLIT)
    if len(train) < 2:
        problems.append(
            f"{dataset_location(dataset_root)}: the {TRAIN_SPLIT} split has {len(train)} scene(s); a semi-supervised split needs at "
            "least 2 (1 labelled and 1 unlabelled)"
        )
    for split in _OTHER_SPLITS:
        shared = [scene_id for scene_id in train if scene_id in dataset.splits.get(split, [])]
        if shared:
            problems.append(f"{dataset_location(dataset_root)}: scenes {shared} are in both the {TRAIN_SPLIT} and the {split} split")
    if problems:
        raise SplitError("; ".join(problems), problems)
    order = np.random.default_rng(int(seed)).permutation(len(train))
    chosen = {train[i] for i in order[: _labelled_count(float(labelled_fraction), len(train))]}
    return SemiSupervisedSplit(
        labelled=tuple(scene_id for scene_id in train if scene_id in chosen),
        unlabelled=tuple(scene_id for scene_id in train if scene_id not in chosen),
        labelled_fraction=float(labelled_fraction),
        seed=int(seed),
        dataset_fingerprint=dataset_fingerprint(dataset),
    )


def write_split(split: SemiSupervisedSplit, path: str | os.PathLike, *, dataset_root: DatasetIndex | str | os.PathLike | None = None) -> Path:
    """Write ``split`` as versioned JSON with a ``sha256`` of its canonical content (atomic).

    Parameters
    ----------
    split
        From :func:`make_split`.
    path
        The JSON file to write.
    dataset_root
        When given, ``path`` may not lie inside it.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    path = Path(path)
    if dataset_root is not None:
        refuse_output_inside(path, datasets=(dataset_location(dataset_root),), what="split file")
    content = split.to_json()
    document = {**content, "sha256": canonical_json_sha256(content)}
    prepare_out_dir(path.parent)
    write_json_atomic(path, document)
    return path


def _scene_list_problems(document: dict, key: str, where: str) -> list[str]:
    value = document.get(key)
    if not isinstance(value, list) or not value or not all(isinstance(s, str) for s in value):
        return [f"{where}: {key}: expected a non-empty list of scene ids, found {value!r}"]
    repeated = sorted({s for s in value if value.count(s) > 1})
    return [f"{where}: {key}: expected each scene once, found {repeated} repeated"] if repeated else []


def _document_problems(document: Any, where: str) -> list[str]:
    if not isinstance(document, dict):
        return [f"{where}: expected a JSON object, found {type(document).__name__}"]
    if document.get("format") != FORMAT_NAME:
        return [f"{where}: format: expected {FORMAT_NAME!r}, found {document.get('format')!r}"]
    if document.get("format_version") != FORMAT_VERSION:
        return [f"{where}: format_version: expected {FORMAT_VERSION}, found {document.get('format_version')!r}"]
    problems = _scene_list_problems(document, "labelled", where) + _scene_list_problems(document, "unlabelled", where)
    if not problems:
        both = sorted(set(document["labelled"]) & set(document["unlabelled"]))
        if both:
            problems.append(f"{where}: expected disjoint parts, found {both} both labelled and unlabelled")
    fraction = document.get("labelled_fraction")
    if isinstance(fraction, bool) or not isinstance(fraction, int | float) or not 0.0 < fraction < 1.0:
        problems.append(f"{where}: labelled_fraction: expected a number in (0, 1), found {fraction!r}")
    seed = document.get("seed")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        problems.append(f"{where}: seed: expected an integer >= 0, found {seed!r}")
    fingerprint = document.get("dataset_fingerprint")
    if not (isinstance(fingerprint, str) and SHA256_HEX.fullmatch(fingerprint)):
        problems.append(f"{where}: dataset_fingerprint: expected 64 lowercase hex digits, found {fingerprint!r}")
    expected_keys = {"format", "format_version", "labelled", "unlabelled", "labelled_fraction", "seed", "dataset_fingerprint", "sha256"}
    unknown = sorted(set(document) - expected_keys)
    if unknown:
        problems.append(f"{where}: expected only the keys {sorted(expected_keys)}, found also {unknown}")
    content = {key: value for key, value in document.items() if key != "sha256"}
    recorded = document.get("sha256")
    try:
        digest = canonical_json_sha256(content)
    except ValueError as exc:
        return problems + [f"{where}: cannot be checksummed ({exc})"]
    if recorded != digest:
        problems.append(
            f"{where}: sha256: the content hashes to {digest}, the file records {recorded!r} "
            "(the file was edited after it was written)"
        )
    return problems


def read_split(path: str | os.PathLike, dataset_root: DatasetIndex | str | os.PathLike | None = None) -> SemiSupervisedSplit:
    """Read a split file written by :func:`write_split`, checking it.

    Parameters
    ----------
    path
        The split JSON file.
    dataset_root
        When given, the split must have been drawn from this dataset (same ``dataset.json``) and
        every scene of it must be a training scene there.

    Raises
    ------
    SplitError
        Naming the file and listing every problem: unreadable, another format or version, a
        checksum that does not match the content, parts not disjoint, another dataset, scenes that
        are not training scenes.
    """
    where = os.fspath(path)
    try:
        document = json.loads(Path(path).read_bytes().decode("utf-8"))
    except FileNotFoundError:
        raise SplitError(f"{where}: expected a semi-supervised split file, found none") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise SplitError(f"{where}: expected the JSON of a semi-supervised split, found unreadable content ({exc})") from None
    problems = _document_problems(document, where)
    if dataset_root is not None and not problems:
        dataset = dataset_index(dataset_root)
        fingerprint = dataset_fingerprint(dataset)
        if document["dataset_fingerprint"] != fingerprint:
            problems.append(
                f"{where}: dataset_fingerprint: drawn from another dataset ({document['dataset_fingerprint'][:12]}...), "
                f"not {dataset_location(dataset_root)} ({fingerprint[:12]}...)"
            )
        train = set(dataset.scene_ids(TRAIN_SPLIT))
        outside = [s for s in document["labelled"] + document["unlabelled"] if s not in train]
        if outside:
            problems.append(f"{where}: scenes {outside} are not in the {TRAIN_SPLIT} split of {dataset_location(dataset_root)}")
    if problems:
        raise SplitError("; ".join(problems), problems)
    return SemiSupervisedSplit(
        labelled=tuple(document["labelled"]),
        unlabelled=tuple(document["unlabelled"]),
        labelled_fraction=float(document["labelled_fraction"]),
        seed=document["seed"],
        dataset_fingerprint=document["dataset_fingerprint"],
    )


__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "ManualLabelLeakError",
    "SemiSupervisedSplit",
    "SplitError",
    "make_split",
    "read_split",
    "write_split",
]
