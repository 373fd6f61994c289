"""The semi-supervised split on a tiny simulated dataset (6 scenes: 4 train, 1 val, 1 test)."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from zendar_dataset.errors import ZendarError
from zendar_dataset.sim.generate import synthesize_dataset

from zendar_baselines.labels.splits import ManualLabelLeakError, SplitError, make_split, read_split, write_split


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return synthesize_dataset(tmp_path_factory.mktemp("split") / "tiny", "tiny", n_scenes=6, seed=0, progress=False)


@pytest.fixture(scope="module")
def document(dataset: Path) -> dict:
    return json.loads((dataset / "dataset.json").read_text())


def edited_dataset(tmp_path: Path, document: dict, **changes) -> Path:
    """A copy of the dataset's ``dataset.json`` alone, with top-level ``changes``."""
    root = tmp_path / "edited"
    root.mkdir()
    (root / "dataset.json").write_text(json.dumps({**document, **changes}))
    return root


@pytest.mark.parametrize(("fraction", "n_labelled"), [(0.25, 1), (0.5, 2), (0.6, 2), (0.7, 3), (0.01, 1), (0.99, 3)])
def test_parts_partition_the_training_scenes(dataset: Path, document: dict, fraction: float, n_labelled: int) -> None:
    train = document["splits"]["train"]
    assert len(train) == 4
    split = make_split(dataset, fraction, seed=7)
    assert len(split.labelled) == n_labelled and len(split.unlabelled) == 4 - n_labelled
    assert not set(split.labelled) & set(split.unlabelled)
    assert sorted(split.labelled + split.unlabelled) == sorted(train)
    others = set(document["splits"]["val"]) | set(document["splits"]["test"])
    assert len(others) == 2 and not others & set(split.labelled + split.unlabelled)
    assert split.labelled == tuple(s for s in train if s in split.labelled)  # dataset order kept
    assert split.dataset_fingerprint == hashlib.sha256((dataset / "dataset.json").read_bytes()).hexdigest()


def test_draw_is_a_seeded_generator_permutation(dataset: Path, document: dict) -> None:
    train = document["splits"]["train"]
    drawn = {}
    for seed in range(12):
        split = make_split(dataset, 0.5, seed)
        assert split == make_split(dataset, 0.5, seed)
        expected = {train[i] for i in np.random.default_rng(seed).permutation(4)[:2]}
        assert set(split.labelled) == expected
        drawn[seed] = split.labelled
    # 6 possible pairs: twelve seeds cannot all draw the same one unless the seed is ignored.
    assert len(set(drawn.values())) > 1


def test_written_file_round_trips_with_canonical_checksum(dataset: Path, tmp_path: Path) -> None:
    split = make_split(dataset, 0.25, seed=3)
    path = write_split(split, tmp_path / "runs" / "split.json", dataset_root=dataset)
    written = json.loads(path.read_text())
    assert written["format"] == "zendar-semisupervised-split" and written["format_version"] == 1
    content = {key: value for key, value in written.items() if key != "sha256"}
    canonical = json.dumps(content, sort_keys=True, separators=(",", ":")).encode()
    assert written["sha256"] == hashlib.sha256(canonical).hexdigest()
    assert read_split(path, dataset) == split

    # Layout does not matter, content does.
    path.write_text(json.dumps(written, indent=4, sort_keys=True))
    assert read_split(path, dataset) == split


def test_edited_file_fails_its_checksum(dataset: Path, tmp_path: Path) -> None:
    split = make_split(dataset, 0.25, seed=3)
    path = write_split(split, tmp_path / "split.json")
    written = json.loads(path.read_text())
    moved = written["unlabelled"][0]
    written["labelled"].append(moved)
    written["unlabelled"].remove(moved)
    path.write_text(json.dumps(written))
    with pytest.raises(SplitError, match=rf"{path}: sha256: .*edited after it was written") as caught:
        read_split(path)
    assert len(caught.value.problems) == 1


def test_every_problem_is_listed(dataset: Path, document: dict, tmp_path: Path) -> None:
    path = tmp_path / "split.json"
    write_split(make_split(dataset, 0.5, seed=0), path)
    written = json.loads(path.read_text())
    written["labelled"].append(written["unlabelled"][0])
    written["seed"] = -1
    path.write_text(json.dumps(written))
    with pytest.raises(SplitError) as caught:
        read_split(path, dataset)
    problems = caught.value.problems
    assert len(problems) == 3
    assert "both labelled and unlabelled" in problems[0]
    assert "seed: expected an integer >= 0, found -1" in problems[1]
    assert "sha256" in problems[2]
    assert all(problem.startswith(str(path)) for problem in problems)


def test_split_of_another_dataset_or_with_foreign_scenes_is_refused(dataset: Path, document: dict, tmp_path: Path) -> None:
    split = make_split(dataset, 0.5, seed=0)
    path = write_split(split, tmp_path / "split.json")
    other = edited_dataset(tmp_path, document, name="renamed")
    with pytest.raises(SplitError, match="drawn from another dataset"):
        read_split(path, other)

    # A consistent file (checksum recomputed) that names a validation scene.
    val_scene = document["splits"]["val"][0]
    forged = type(split)(
        labelled=(*split.labelled, val_scene),
        unlabelled=split.unlabelled,
        labelled_fraction=split.labelled_fraction,
        seed=split.seed,
        dataset_fingerprint=split.dataset_fingerprint,
    )
    write_split(forged, path)
    assert read_split(path) == forged
    with pytest.raises(SplitError, match=rf"scenes \['{val_scene}'\] are not in the train split"):
        read_split(path, dataset)


def test_unreadable_or_other_version_files_are_named(dataset: Path, tmp_path: Path) -> None:
    path = tmp_path / "split.json"
    with pytest.raises(SplitError, match=rf"{path}: expected a semi-supervised split file, found none"):
        read_split(path)
    path.write_text("{")
    with pytest.raises(SplitError, match=rf"{path}: expected the JSON of a semi-supervised split"):
        read_split(path)
    write_split(make_split(dataset, 0.5, seed=0), path)
    written = json.loads(path.read_text())
    path.write_text(json.dumps({**written, "format_version": 2}))
    with pytest.raises(SplitError, match="format_version: expected 1, found 2"):
        read_split(path)


def test_too_few_training_scenes_and_bad_arguments(dataset: Path, document: dict, tmp_path: Path) -> None:
    single = edited_dataset(tmp_path, document, splits={**document["splits"], "train": document["splits"]["train"][:1]})
    with pytest.raises(SplitError, match="the train split has 1 scene"):
        make_split(single, 0.5, seed=0)
    with pytest.raises(SplitError) as caught:
        make_split(dataset, 1.0, seed=-3)
    assert len(caught.value.problems) == 2
    assert "labelled_fraction: expected a number in (0, 1), found 1.0" in caught.value.problems[0]
    assert "seed: expected an integer >= 0, found -3" in caught.value.problems[1]


def test_manual_labels_of_unlabelled_scenes_are_guarded(dataset: Path, document: dict) -> None:
    split = make_split(dataset, 0.5, seed=1)
    split.check_manual_label_use(split.labelled)
    split.check_manual_label_use([*split.labelled, *document["splits"]["val"]])
    with pytest.raises(ManualLabelLeakError, match=rf"\['{split.unlabelled[1]}'\]"):
        split.check_manual_label_use([*split.labelled, split.unlabelled[1]])
    with pytest.raises(ManualLabelLeakError, match=r"2 scene\(s\)"):
        split.check_manual_label_use(document["splits"]["train"])


def test_split_file_inside_the_dataset_is_refused(dataset: Path) -> None:
    split = make_split(dataset, 0.5, seed=0)
    with pytest.raises(ZendarError, match="inside the dataset"):
        write_split(split, dataset / "split.json", dataset_root=dataset)
    assert not (dataset / "split.json").exists()
