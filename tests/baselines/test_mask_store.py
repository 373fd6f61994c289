"""The automatic-label side store: round trip, resume, start-over, refusals and tampering."""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np
import pytest

from zendar_dataset.errors import ZendarError
from zendar_dataset.format.schema import FORMAT_NAME, FORMAT_VERSION
from zendar_dataset.temporary_files import forget, temporary_sibling

from zendar_baselines.labels.mask_store import MANIFEST_FILENAME, MaskStore, MaskStoreError

PARAMETERS = {"drop_db": 6.0, "window_bins": [5, 3]}
CODE = "0.1.0+test"


def make_dataset(root: Path, scene_ids: list[str], name: str = "hand-made") -> Path:
    """A dataset root holding only ``dataset.json`` (the store never opens a scene)."""
    root.mkdir(parents=True)
    document = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "name": name,
        "splits": {"train": list(scene_ids), "val": [], "test": []},
        "scenes": {scene_id: {"path": f"scenes/{scene_id}.zarr"} for scene_id in scene_ids},
    }
    (root / "dataset.json").write_text(json.dumps(document))
    return root


def radar_masks(seed: int, n_frames: int = 4, shape: tuple[int, int] = (6, 5)) -> dict:
    rng = np.random.default_rng(seed)
    return {
        radar: (
            np.sort(rng.choice(10**9, size=n_frames, replace=False)).astype(np.int64),
            rng.integers(0, 3, size=(n_frames, *shape), dtype=np.uint8),
        )
        for radar in ("left", "right")
    }


def snapshot(directory: Path) -> dict[str, bytes | None]:
    """Every entry under ``directory`` with its bytes (None for a directory)."""
    return {
        str(path.relative_to(directory)): (None if path.is_dir() else path.read_bytes())
        for path in sorted(directory.rglob("*"))
    }


@pytest.fixture
def dataset(tmp_path: Path) -> Path:
    return make_dataset(tmp_path / "data", ["scene-0000", "scene-0001", "scene-0002"])


def test_round_trip_and_manifest(dataset: Path, tmp_path: Path) -> None:
    out = tmp_path / "autolabels"
    store = MaskStore.create(out, dataset, PARAMETERS, code_version=CODE)
    written = {"scene-0000": radar_masks(0), "scene-0002": radar_masks(2, n_frames=3, shape=(7, 4))}
    for scene_id, masks in written.items():
        store.write_scene(scene_id, masks)

    reopened = MaskStore.open(out, dataset, parameters=PARAMETERS, code_version=CODE)
    assert reopened.scene_ids() == ["scene-0000", "scene-0002"]
    for scene_id, masks in written.items():
        read = reopened.scene(scene_id)
        assert set(read) == {"left", "right"}
        for radar, (timestamp_ns, mask) in masks.items():
            assert read[radar][0].dtype == np.int64 and read[radar][1].dtype == np.uint8
            np.testing.assert_array_equal(read[radar][0], timestamp_ns)
            np.testing.assert_array_equal(read[radar][1], mask)

    manifest = json.loads((out / MANIFEST_FILENAME).read_text())
    assert manifest["format"] == "zendar-autolabels" and manifest["format_version"] == 1
    assert manifest["code_version"] == CODE
    assert manifest["parameters"] == {"drop_db": 6.0, "window_bins": [5, 3]}
    assert manifest["dataset"]["root"] == str(dataset.resolve())
    assert manifest["dataset"]["fingerprint"] == hashlib.sha256((dataset / "dataset.json").read_bytes()).hexdigest()
    entry = manifest["scenes"]["scene-0002"]
    assert entry["file"] == "scene-0002.npz"
    assert entry["sha256"] == hashlib.sha256((out / "scene-0002.npz").read_bytes()).hexdigest()
    assert entry["radars"]["left"] == {"n_frames": 3, "shape": [3, 7, 4]}
    assert sorted(os.listdir(out)) == [MANIFEST_FILENAME, "scene-0000.npz", "scene-0002.npz"]
    assert not any(name.startswith(".") for name in os.listdir(out))


def test_resume_keeps_finished_scenes(dataset: Path, tmp_path: Path) -> None:
    out = tmp_path / "autolabels"
    MaskStore.create(out, dataset, PARAMETERS, code_version=CODE).write_scene("scene-0000", radar_masks(0))
    # A later run with the same parameters (in another order and as a tuple) resumes.
    resumed = MaskStore.create(out, dataset, {"window_bins": (5, 3), "drop_db": 6.0}, code_version=CODE)
    assert resumed.has_scene("scene-0000", PARAMETERS, CODE)
    assert not resumed.has_scene("scene-0001", PARAMETERS, CODE)
    assert not resumed.has_scene("scene-0000", {**PARAMETERS, "drop_db": 3.0}, CODE)
    assert not resumed.has_scene("scene-0000", PARAMETERS, "0.1.0+other")
    resumed.write_scene("scene-0001", radar_masks(1))
    assert MaskStore.open(out, dataset).scene_ids() == ["scene-0000", "scene-0001"]


@pytest.mark.parametrize("change", ["parameters", "code_version"])
def test_other_parameters_or_code_start_over_inside_the_store(dataset: Path, tmp_path: Path, change: str) -> None:
    out = tmp_path / "autolabels"
    store = MaskStore.create(out, dataset, PARAMETERS, code_version=CODE)
    store.write_scene("scene-0000", radar_masks(0))
    (out / "notes.txt").write_text("mine")
    parameters = {**PARAMETERS, "drop_db": 3.0} if change == "parameters" else PARAMETERS
    code = "0.1.0+edited" if change == "code_version" else CODE

    with pytest.raises(MaskStoreError, match=change):
        MaskStore.open(out, dataset, parameters=parameters, code_version=code)
    restarted = MaskStore.create(out, dataset, parameters, code_version=code)

    assert restarted.scene_ids() == []
    assert not (out / "scene-0000.npz").exists()
    assert (out / "notes.txt").read_text() == "mine"
    assert json.loads((out / MANIFEST_FILENAME).read_text())["scenes"] == {}


def test_flipped_byte_in_scene_file_is_named(dataset: Path, tmp_path: Path) -> None:
    out = tmp_path / "autolabels"
    store = MaskStore.create(out, dataset, PARAMETERS, code_version=CODE)
    store.write_scene("scene-0000", radar_masks(0))
    path = out / "scene-0000.npz"
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0x01
    path.write_bytes(bytes(data))

    with pytest.raises(MaskStoreError, match=r"scene-0000\.npz: SHA-256"):
        MaskStore.open(out, dataset)
    with pytest.raises(MaskStoreError, match=r"scene-0000\.npz: SHA-256"):
        store.scene("scene-0000")
    assert not store.has_scene("scene-0000", PARAMETERS, CODE)
    # Opening without verification still works: reading the scene is what fails.
    assert MaskStore.open(out, verify=False).scene_ids() == ["scene-0000"]


def test_every_damaged_scene_is_listed(dataset: Path, tmp_path: Path) -> None:
    out = tmp_path / "autolabels"
    store = MaskStore.create(out, dataset, PARAMETERS, code_version=CODE)
    for index, scene_id in enumerate(["scene-0000", "scene-0001", "scene-0002"]):
        store.write_scene(scene_id, radar_masks(index))
    (out / "scene-0000.npz").unlink()
    with open(out / "scene-0002.npz", "ab") as handle:
        handle.write(b"\0")

    with pytest.raises(MaskStoreError) as caught:
        MaskStore.open(out)
    problems = caught.value.problems
    assert len(problems) == 2
    assert "scene-0000.npz" in problems[0] and "found no file" in problems[0]
    assert "scene-0002.npz" in problems[1] and "SHA-256" in problems[1]


def test_edited_manifest_is_refused(dataset: Path, tmp_path: Path) -> None:
    out = tmp_path / "autolabels"
    MaskStore.create(out, dataset, PARAMETERS, code_version=CODE).write_scene("scene-0001", radar_masks(1))
    manifest_path = out / MANIFEST_FILENAME
    original = json.loads(manifest_path.read_text())

    # Shape edited consistently with n_frames: only the file's own array headers reveal it.
    edited = json.loads(json.dumps(original))
    edited["scenes"]["scene-0001"]["radars"]["left"] = {"n_frames": 4, "shape": [4, 6, 6]}
    manifest_path.write_text(json.dumps(edited))
    with pytest.raises(MaskStoreError, match=r"scene-0001\.npz: left/masks: expected uint8 \[4, 6, 6\].*found uint8 \[4, 6, 5\]"):
        MaskStore.open(out)

    edited = json.loads(json.dumps(original))
    edited["scenes"]["scene-0001"]["radars"]["right"]["n_frames"] = 5
    edited["scenes"]["scene-0001"]["file"] = "../elsewhere.npz"
    manifest_path.write_text(json.dumps(edited))
    with pytest.raises(MaskStoreError) as caught:
        MaskStore.open(out)
    assert len(caught.value.problems) == 2
    assert all(str(manifest_path) in problem for problem in caught.value.problems)

    manifest_path.write_text(json.dumps({**original, "format_version": 2}))
    with pytest.raises(MaskStoreError, match="format_version: expected 1, found 2"):
        MaskStore.open(out)
    before = snapshot(out)
    with pytest.raises(MaskStoreError, match="format_version"):
        MaskStore.create(out, dataset, PARAMETERS, code_version=CODE)
    assert snapshot(out) == before

    manifest_path.write_text(json.dumps(original)[:-5])
    with pytest.raises(MaskStoreError, match=rf"{MANIFEST_FILENAME}: expected the auto-label store's JSON"):
        MaskStore.open(out)


def test_foreign_directory_is_left_untouched(dataset: Path, tmp_path: Path) -> None:
    out = tmp_path / "photos"
    (out / "2019").mkdir(parents=True)
    (out / "2019" / "beach.jpg").write_bytes(b"\xff\xd8\xff" + bytes(range(256)))
    (out / "scene-0000.npz").write_bytes(b"not ours")
    (out / ".hidden").write_text("x")
    before = snapshot(out)

    with pytest.raises(MaskStoreError, match=r"holds someone else's files \(3: \.hidden, 2019, scene-0000\.npz\)"):
        MaskStore.create(out, dataset, PARAMETERS, code_version=CODE)
    assert snapshot(out) == before

    # Someone else's manifest.json is not ours either.
    (out / MANIFEST_FILENAME).write_text(json.dumps({"format": "photo-album"}))
    before = snapshot(out)
    with pytest.raises(MaskStoreError, match="someone else's files"):
        MaskStore.create(out, dataset, PARAMETERS, code_version=CODE)
    assert snapshot(out) == before


def test_out_dir_inside_dataset_is_refused(dataset: Path) -> None:
    before = snapshot(dataset)
    for inside in (dataset, dataset / "autolabels", dataset / "scenes" / "x"):
        with pytest.raises(ZendarError, match="inside the dataset"):
            MaskStore.create(inside, dataset, PARAMETERS, code_version=CODE)
    assert snapshot(dataset) == before


def test_store_of_another_dataset_is_refused(dataset: Path, tmp_path: Path) -> None:
    other = make_dataset(tmp_path / "other", ["scene-0000"], name="other")
    out = tmp_path / "autolabels"
    MaskStore.create(out, dataset, PARAMETERS, code_version=CODE).write_scene("scene-0000", radar_masks(0))
    before = snapshot(out)

    with pytest.raises(MaskStoreError, match="made from another dataset"):
        MaskStore.create(out, other, PARAMETERS, code_version=CODE)
    with pytest.raises(MaskStoreError, match="made from another dataset"):
        MaskStore.open(out, other)
    assert snapshot(out) == before


def test_bad_scene_input_lists_every_problem_and_writes_nothing(dataset: Path, tmp_path: Path) -> None:
    out = tmp_path / "autolabels"
    store = MaskStore.create(out, dataset, PARAMETERS, code_version=CODE)
    before = snapshot(out)
    masks = np.zeros((3, 4, 5), np.uint8)
    masks[0, 1, 2] = 3
    bad = {
        "left": (np.array([1, 2, 3]), masks),
        "right": (np.array([1, 3, 2]), np.zeros((2, 4, 5), np.int16)),
        "a/b": (np.array([1]), np.zeros((1, 4, 5), np.uint8)),
        "top": (np.array([1, 2]), np.zeros((3, 4, 5), np.uint8)),
    }
    with pytest.raises(MaskStoreError) as caught:
        store.write_scene("scene-0009", bad)
    problems = caught.value.problems
    assert len(problems) == 6
    assert "scene-0009: not a scene of the dataset" in problems[0]
    assert "radar left: masks: expected values in [0, 1, 2], found 1 cells above 2" in problems[1]
    assert "radar right: timestamp_ns: expected strictly increasing" in problems[2]
    assert "radar right: masks: expected uint8 [N, R, D], found int16" in problems[3]
    assert "expected radar names without '/'" in problems[4] and "'a/b'" in problems[4]
    assert "radar top: expected one mask per timestamp, found 3 masks and 2 timestamps" in problems[5]
    assert snapshot(out) == before


def test_missing_store_and_missing_scene_are_named(dataset: Path, tmp_path: Path) -> None:
    with pytest.raises(MaskStoreError, match="expected a directory, found nothing"):
        MaskStore.open(tmp_path / "nowhere")
    (tmp_path / "empty").mkdir()
    with pytest.raises(MaskStoreError, match=rf"empty/{MANIFEST_FILENAME}: expected the auto-label store's"):
        MaskStore.open(tmp_path / "empty")
    store = MaskStore.create(tmp_path / "empty", dataset, PARAMETERS, code_version=CODE)
    with pytest.raises(MaskStoreError, match="holds no labels of scene 'scene-0001'"):
        store.scene("scene-0001")
    (tmp_path / "a-file").write_text("x")
    with pytest.raises(MaskStoreError, match="a-file/autolabels: cannot be created"):
        MaskStore.create(tmp_path / "a-file" / "autolabels", dataset, PARAMETERS, code_version=CODE)
    with pytest.raises(MaskStoreError, match="a-file: exists and is not a directory"):
        MaskStore.create(tmp_path / "a-file", dataset, PARAMETERS, code_version=CODE)


def test_interrupted_run_leftovers_are_cleared(dataset: Path, tmp_path: Path) -> None:
    out = tmp_path / "autolabels"
    out.mkdir()
    # A killed first run left only a temporary of its manifest: the directory is still ours to use.
    leftover = temporary_sibling(out / MANIFEST_FILENAME)
    leftover.write_text("{")
    forget(leftover)
    store = MaskStore.create(out, dataset, PARAMETERS, code_version=CODE)
    assert sorted(os.listdir(out)) == [MANIFEST_FILENAME]

    # Killed between a scene file's rename and the manifest update: the scene is not counted as done.
    store.write_scene("scene-0000", radar_masks(0))
    (out / "scene-0001.npz").write_bytes((out / "scene-0000.npz").read_bytes())
    resumed = MaskStore.create(out, dataset, PARAMETERS, code_version=CODE)
    assert resumed.scene_ids() == ["scene-0000"]
    assert not resumed.has_scene("scene-0001", PARAMETERS, CODE)
