"""The semi-supervised split of time segments, on a tiny simulated dataset (6 scenes of 10 label frames:
4 train, 1 val, 1 test), and its use by the training steps."""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
from pathlib import Path

import numpy as np
import pytest

from zendar_dataset.detection.boxes import nearest_label_frame
from zendar_dataset.errors import ZendarError
from zendar_dataset.eval.car_counts import dataset_car_counts
from zendar_dataset.format.reader import open_dataset
from zendar_dataset.sim.generate import synthesize_dataset

from zendar_baselines.bench.configs import get_config
from zendar_baselines.bench.context import RunContext
from zendar_baselines.bench.steps import STORE_DIR, _frames, write_label_masks
from zendar_baselines.cnn.mask_frames import MaskFrames, MaskFrameSubset
from zendar_baselines.fingerprints import canonical_json_sha256
from zendar_baselines.labels.mask_classes import UNCERTAIN
from zendar_baselines.labels.mask_store import MaskStore
from zendar_baselines.labels.masks import scene_masks
from zendar_baselines.labels.splits import (
    WHOLE_SCENE,
    ManualLabelLeakError,
    SplitError,
    make_split,
    read_split,
    scene_segments,
    write_split,
)

BANDS_M = {"near": (0.0, 15.0), "mid": (15.0, 30.0), "far": (30.0, 60.0)}


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return synthesize_dataset(tmp_path_factory.mktemp("split") / "tiny", "tiny", n_scenes=6, seed=0, progress=False)


@pytest.fixture(scope="module")
def document(dataset: Path) -> dict:
    return json.loads((dataset / "dataset.json").read_text())


@pytest.fixture(scope="module")
def frames_ns(dataset: Path, document: dict) -> dict[str, np.ndarray]:
    """Each training scene's label-frame (first SAR stream) timestamps."""
    index = open_dataset(dataset)
    out = {}
    for scene_id in document["splits"]["train"]:
        with index.open_scene(scene_id) as reader:
            out[scene_id] = reader.timestamps(f"sar/{reader.sensors('sar')[0]}")
    return out


def edited_dataset(tmp_path: Path, document: dict, **changes) -> Path:
    """A copy of the dataset's ``dataset.json`` alone, with top-level ``changes``."""
    root = tmp_path / "edited"
    root.mkdir()
    (root / "dataset.json").write_text(json.dumps({**document, **changes}))
    return root


# --- segments ------------------------------------------------------------------------------------


@pytest.mark.parametrize("per_segment", [1, 3, 4, 10])
def test_an_instant_lies_in_the_segment_of_its_nearest_label_frame(per_segment: int) -> None:
    rng = np.random.default_rng(0)
    stamps = np.cumsum(rng.integers(90_000_000, 110_000_001, size=10)).astype(np.int64)  # irregular, odd gaps too
    segments = scene_segments(stamps, per_segment)
    assert len(segments) == -(-10 // per_segment)
    assert all(a[1] == b[0] for a, b in itertools.pairwise(segments))  # contiguous
    queries = np.concatenate([rng.integers(stamps[0], stamps[-1], 2000), stamps,
                              (stamps[:-1] + stamps[1:]) // 2, (stamps[:-1] + stamps[1:]) // 2 + 1])
    for t in queries.tolist():
        nearest = int(np.flatnonzero(stamps == nearest_label_frame(stamps, t))[0])
        inside = [k for k, (start, end) in enumerate(segments) if start <= t < end]
        assert inside == [nearest // per_segment], t
    # Half a spacing beyond the outer frames, and not further.
    assert segments[0][0] == stamps[0] - (stamps[1] - stamps[0]) // 2
    assert segments[-1][1] - 1 == stamps[-1] + (stamps[-1] - stamps[-2]) // 2


# --- drawing -------------------------------------------------------------------------------------


@pytest.mark.parametrize(("fraction", "n_labelled"), [(0.25, 2), (0.5, 4), (0.01, 1), (0.99, 7)])
def test_parts_partition_the_training_segments(dataset: Path, document: dict, frames_ns: dict, fraction: float,
                                               n_labelled: int) -> None:
    train = document["splits"]["train"]
    split = make_split(dataset, fraction, seed=7, frames_per_segment=5)
    assert split.n_segments == 8  # 4 scenes of 10 frames
    spans = [(scene_id, span) for scene_id, scene_spans in split.labelled_segments.items() for span in scene_spans]
    assert len(spans) == n_labelled
    for scene_id, span in spans:
        assert span in scene_segments(frames_ns[scene_id], 5)
    assert split.labelled == tuple(s for s in train if s in split.labelled_segments)  # dataset order kept
    assert split.unlabelled == tuple(s for s in train if s not in split.labelled_segments)
    others = set(document["splits"]["val"]) | set(document["splits"]["test"])
    assert len(others) == 2 and not others & set(split.labelled + split.unlabelled)
    assert split.dataset_fingerprint == hashlib.sha256((dataset / "dataset.json").read_bytes()).hexdigest()


def test_draw_is_a_seeded_permutation_of_all_training_segments(dataset: Path, document: dict, frames_ns: dict) -> None:
    every = [(s, span) for s in document["splits"]["train"] for span in scene_segments(frames_ns[s], 3)]
    assert len(every) == 16  # 4 scenes of 3 + 3 + 3 + 1 frames
    drawn = set()
    for seed in range(6):
        split = make_split(dataset, 0.25, seed, frames_per_segment=3)
        assert split == make_split(dataset, 0.25, seed, frames_per_segment=3)
        expected = sorted(every[i] for i in np.random.default_rng(seed).permutation(16)[:4])
        got = sorted((s, span) for s, spans in split.labelled_segments.items() for span in spans)
        assert got == expected
        drawn.add(tuple(got))
    assert len(drawn) > 1


def test_labelled_cars_are_counted_in_the_labelled_segments_alone(dataset: Path) -> None:
    split = make_split(dataset, 0.25, seed=5, frames_per_segment=3)
    index = open_dataset(dataset)
    cars = {band: set() for band in BANDS_M}
    for scene_id, spans in split.labelled_segments.items():
        with index.open_scene(scene_id) as reader:
            labels = reader.labels()
        for row in range(labels["timestamp_ns"].size):
            t = int(labels["timestamp_ns"][row])
            if not any(start <= t < end for start, end in spans):
                continue
            r = float(np.hypot(labels["x"][row], labels["y"][row]))
            for band, (low, high) in BANDS_M.items():
                if low <= r < high:
                    cars[band].add((scene_id, int(labels["track_id"][row])))
    assert {band: split.labelled_cars[band] for band in BANDS_M} == {band: len(c) for band, c in cars.items()}
    assert sum(split.labelled_cars[band] for band in BANDS_M) > 0


def test_dataset_counts_are_the_distinct_tracks_of_each_split_per_band(dataset: Path, document: dict) -> None:
    counts = dataset_car_counts(dataset)
    index = open_dataset(dataset)
    for split, scene_ids in document["splits"].items():
        cars = {band: set() for band in BANDS_M}
        for scene_id in scene_ids:
            with index.open_scene(scene_id) as reader:
                labels = reader.labels()
            for x, y, track in zip(labels["x"].tolist(), labels["y"].tolist(), labels["track_id"].tolist()):
                for band, (low, high) in BANDS_M.items():
                    if low <= (x * x + y * y) ** 0.5 < high:
                        cars[band].add((scene_id, track))
        assert {band: counts[split].cars[band] for band in BANDS_M} == {band: len(c) for band, c in cars.items()}, split
        assert sum(sum(kinds.values()) for kinds in [counts[split].by_kind["all"]]) == counts[split].cars["all"]
        assert "unknown" not in counts[split].by_kind["all"]  # every car got a kind from the ego's headings
    assert counts["train"].cars["all"] > 0


def test_too_few_labelled_cars_for_the_fraction_is_refused_with_the_counts(dataset: Path) -> None:
    split = make_split(dataset, 0.25, seed=5, frames_per_segment=3)
    counts = ", ".join(f"{band} {split.labelled_cars[band]}" for band in BANDS_M)
    with pytest.raises(SplitError, match=r"too few labelled cars for labelled_fraction 0.25") as caught:
        make_split(dataset, 0.25, seed=5, frames_per_segment=3, min_cars_per_band=1000)
    message = str(caught.value)
    assert f"4 of 16 training segments (seed 5) hold {counts} distinct labelled cars" in message
    assert "at least 1000 per band" in message and "raise the labelled fraction, or simulate more" in message
    assert "the whole train split holds near" in message


# --- the file ------------------------------------------------------------------------------------


def test_written_file_round_trips_with_canonical_checksum(dataset: Path, tmp_path: Path) -> None:
    split = make_split(dataset, 0.25, seed=3)
    path = write_split(split, tmp_path / "runs" / "split.json", dataset_root=dataset)
    written = json.loads(path.read_text())
    assert written["format"] == "zendar-semisupervised-split" and written["format_version"] == 2
    assert set(written["labelled_segments"]) == set(written["labelled"])
    content = {key: value for key, value in written.items() if key != "sha256"}
    canonical = json.dumps(content, sort_keys=True, separators=(",", ":")).encode()
    assert written["sha256"] == hashlib.sha256(canonical).hexdigest()
    assert read_split(path, dataset) == split

    # Layout does not matter, content does.
    path.write_text(json.dumps(written, indent=4, sort_keys=True))
    assert read_split(path, dataset) == split


def test_edited_file_fails_its_checksum(dataset: Path, tmp_path: Path) -> None:
    split = make_split(dataset, 0.25, seed=3, frames_per_segment=5)
    path = write_split(split, tmp_path / "split.json")
    written = json.loads(path.read_text())
    scene_id = written["labelled"][0]
    start, end = written["labelled_segments"][scene_id][0]
    written["labelled_segments"][scene_id][0] = [start - 10**9, end]  # a second more of manual labels
    path.write_text(json.dumps(written))
    with pytest.raises(SplitError, match=rf"{path}: sha256: .*edited after it was written") as caught:
        read_split(path)
    assert len(caught.value.problems) == 1


def test_every_problem_is_listed(dataset: Path, tmp_path: Path) -> None:
    path = tmp_path / "split.json"
    write_split(make_split(dataset, 0.5, seed=0, frames_per_segment=5), path)
    written = json.loads(path.read_text())
    written["labelled"].append(written["unlabelled"][0] if written["unlabelled"] else written["labelled"][0])
    written["seed"] = -1
    written["labelled_segments"][written["labelled"][0]] = [[5, 3]]
    path.write_text(json.dumps(written))
    with pytest.raises(SplitError) as caught:
        read_split(path, dataset)
    problems = caught.value.problems
    assert any("both labelled and unlabelled" in p or "expected each scene once" in p for p in problems)
    assert any("labelled_segments: expected the scenes of labelled" in p for p in problems)
    assert any("start < end" in p for p in problems)
    assert any("seed: expected an integer >= 0, found -1" in p for p in problems)
    assert "sha256" in problems[-1]
    assert all(problem.startswith(str(path)) for problem in problems)


def test_split_of_another_dataset_or_with_foreign_scenes_is_refused(dataset: Path, document: dict, tmp_path: Path) -> None:
    split = make_split(dataset, 0.5, seed=0)
    path = write_split(split, tmp_path / "split.json")
    other = edited_dataset(tmp_path, document, name="renamed")
    with pytest.raises(SplitError, match="drawn from another dataset"):
        read_split(path, other)

    # A consistent file (checksum recomputed) that names a validation scene.
    val_scene = document["splits"]["val"][0]
    forged = dataclasses.replace(split, labelled=(*split.labelled, val_scene),
                                 labelled_segments={**split.labelled_segments, val_scene: ((0, 10),)})
    write_split(forged, path)
    assert read_split(path) == forged
    with pytest.raises(SplitError, match=rf"scenes \['{val_scene}'\] are not in the train split"):
        read_split(path, dataset)


def test_version_1_files_are_read_as_whole_scenes(dataset: Path, document: dict, tmp_path: Path) -> None:
    train = document["splits"]["train"]
    content = {"format": "zendar-semisupervised-split", "format_version": 1, "labelled": train[:1],
               "unlabelled": train[1:], "labelled_fraction": 0.25, "seed": 0,
               "dataset_fingerprint": hashlib.sha256((dataset / "dataset.json").read_bytes()).hexdigest()}
    path = tmp_path / "old.json"
    path.write_text(json.dumps({**content, "sha256": canonical_json_sha256(content)}))
    split = read_split(path, dataset)
    assert split.labelled_segments == {train[0]: (WHOLE_SCENE,)} and split.frames_per_segment == 0
    stamps = np.array([1, 10**18, 2 * 10**18], np.int64)
    assert split.is_labelled(train[0], stamps).all() and not split.is_labelled(train[1], stamps).any()
    # Written back, it stays a version-1 file, byte for byte the same content.
    again = write_split(split, tmp_path / "again.json")
    assert json.loads(again.read_text()) == json.loads(path.read_text())


def test_unreadable_or_unknown_version_files_are_named(dataset: Path, tmp_path: Path) -> None:
    path = tmp_path / "split.json"
    with pytest.raises(SplitError, match=rf"{path}: expected a semi-supervised split file, found none"):
        read_split(path)
    path.write_text("{")
    with pytest.raises(SplitError, match=rf"{path}: expected the JSON of a semi-supervised split"):
        read_split(path)
    write_split(make_split(dataset, 0.5, seed=0), path)
    written = json.loads(path.read_text())
    path.write_text(json.dumps({**written, "format_version": 3}))
    with pytest.raises(SplitError, match=r"format_version: expected one of \[1, 2\], found 3"):
        read_split(path)


def test_too_few_training_segments_and_bad_arguments(dataset: Path, document: dict, tmp_path: Path) -> None:
    single = edited_dataset(tmp_path, document, splits=dict(document["splits"], train=document["splits"]["train"][:1]))
    (single / "scenes").symlink_to(dataset / "scenes")
    with pytest.raises(SplitError, match="the train split has 1 segment"):
        make_split(single, 0.5, seed=0, frames_per_segment=10)
    with pytest.raises(SplitError) as caught:
        make_split(dataset, 1.0, seed=-3, frames_per_segment=0, min_cars_per_band=-1)
    problems = caught.value.problems
    assert len(problems) == 4
    assert "labelled_fraction: expected a number in (0, 1), found 1.0" in problems[0]
    assert "seed: expected an integer >= 0, found -3" in problems[1]
    assert "frames_per_segment: expected an integer >= 1, found 0" in problems[2]
    assert "min_cars_per_band: expected an integer >= 0, found -1" in problems[3]


def test_split_file_inside_the_dataset_is_refused(dataset: Path) -> None:
    split = make_split(dataset, 0.5, seed=0)
    with pytest.raises(ZendarError, match="inside the dataset"):
        write_split(split, dataset / "split.json", dataset_root=dataset)
    assert not (dataset / "split.json").exists()


# --- the guard -----------------------------------------------------------------------------------


def test_manual_labels_outside_the_labelled_segments_are_guarded(dataset: Path, document: dict) -> None:
    split = make_split(dataset, 0.25, seed=1, frames_per_segment=3)
    index = open_dataset(dataset)
    scene_id = split.labelled[0]
    (start, end), *_ = split.labelled_segments[scene_id]
    split.check_manual_label_use(split.labelled)
    split.check_manual_label_use([*split.labelled, *document["splits"]["val"]])
    split.check_manual_label_times(scene_id, [start, end - 1])
    with pytest.raises(ManualLabelLeakError, match=rf"{scene_id} at 1 time\(s\) outside its labelled segments .*first at {end}"):
        split.check_manual_label_times(scene_id, [start, end])
    if split.unlabelled:
        with pytest.raises(ManualLabelLeakError, match=rf"\['{split.unlabelled[0]}'\]"):
            split.check_manual_label_use([*split.labelled, split.unlabelled[0]])
        with index.open_scene(split.unlabelled[0]) as reader, pytest.raises(ManualLabelLeakError):
            split.manual_labels(reader)
    with index.open_scene(scene_id) as reader:
        full = reader.labels()
        kept = split.manual_labels(reader)
        assert split.labelled_view(reader).labels()["timestamp_ns"].tolist() == kept["timestamp_ns"].tolist()
        assert split.labelled_view(reader).scene_id == scene_id  # everything else is the scene's
    inside = np.zeros(full["timestamp_ns"].size, bool)
    for a, b in split.labelled_segments[scene_id]:
        inside |= (full["timestamp_ns"] >= a) & (full["timestamp_ns"] < b)
    assert inside.any() and not inside.all()
    for name, values in full.items():
        np.testing.assert_array_equal(kept[name], values[inside])


# --- in training ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def run(dataset: Path, tmp_path_factory: pytest.TempPathFactory) -> RunContext:
    return RunContext.open(dataset, get_config("tiny"), tmp_path_factory.mktemp("run"), "cpu")


class _ShiftedOutside:
    """A scene whose labels outside ``spans`` are moved 5 m sideways (what a leak would carry into masks)."""

    def __init__(self, reader, spans):
        self._reader, self._spans = reader, spans

    def labels(self):
        labels = {name: values.copy() for name, values in self._reader.labels().items()}
        outside = np.ones(labels["timestamp_ns"].size, bool)
        for a, b in self._spans:
            outside &= ~((labels["timestamp_ns"] >= a) & (labels["timestamp_ns"] < b))
        labels["y"][outside] += 5.0
        return labels

    def __getattr__(self, name):
        return getattr(self._reader, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._reader.close()


def test_label_masks_hold_the_labelled_segments_alone(run: RunContext, tmp_path: Path, monkeypatch) -> None:
    split = make_split(run.dataset, 0.4, seed=2, frames_per_segment=3)
    write_label_masks(run, split, tmp_path / "a")
    store = MaskStore.open(tmp_path / "a" / STORE_DIR, run.dataset)
    assert sorted(store.scene_ids()) == sorted(split.labelled)
    checked_inside = checked_outside = 0
    for scene_id in split.labelled:
        with run.dataset.open_scene(scene_id) as reader:
            for radar in reader.sensors("radar"):
                timestamps, masks = store.scene(scene_id)[radar]
                _, full = scene_masks(reader, radar, "labels", progress=False)
                inside = split.is_labelled(scene_id, timestamps)
                np.testing.assert_array_equal(masks[inside], full[inside])  # the cube's nearest frame is labelled
                assert np.all(masks[~inside] == UNCERTAIN)
                checked_inside += int(inside.sum())
                checked_outside += int((~inside).sum())
    assert checked_inside and checked_outside

    # Labels outside the segments changed: the masks do not move.
    opened = run.dataset.open_scene
    monkeypatch.setattr(run.dataset, "open_scene",
                        lambda scene_id, **kw: _ShiftedOutside(opened(scene_id, **kw), split.labelled_segments.get(scene_id, ())))
    write_label_masks(run, split, tmp_path / "b")
    shifted = MaskStore.open(tmp_path / "b" / STORE_DIR, run.dataset)
    for scene_id in split.labelled:
        for radar, (timestamps, masks) in store.scene(scene_id).items():
            np.testing.assert_array_equal(shifted.scene(scene_id)[radar][1], masks)


def test_supervised_samples_are_the_labelled_cubes_pretraining_sees_all(run: RunContext, tmp_path: Path) -> None:
    split = make_split(run.dataset, 0.4, seed=2, frames_per_segment=3)
    write_label_masks(run, split, tmp_path)
    store_dir = tmp_path / STORE_DIR
    labelled = _frames(run, list(split.labelled), store_dir, split)
    everything = _frames(run, list(split.labelled), store_dir)
    store = MaskStore.open(store_dir, run.dataset)
    expected_targets = []
    n_all = 0
    for scene_id in split.labelled:
        for radar, (timestamps, masks) in sorted(store.scene(scene_id).items(),
                                                 key=lambda item: run.dataset.open_scene(scene_id).sensors("radar").index(item[0])):
            newest = np.arange(timestamps.size)  # one sample per cube: the first windows are padded
            n_all += newest.size
            expected_targets += [masks[i] for i in newest if split.is_labelled(scene_id, timestamps[i : i + 1])[0]]
    assert len(everything) == n_all and 0 < len(labelled) == len(expected_targets) < n_all
    for k, target in enumerate(expected_targets):
        np.testing.assert_array_equal(labelled[k][1].numpy(), target)
        assert not np.all(target == UNCERTAIN)


def test_mask_frame_subset_serves_and_counts_the_kept_samples() -> None:
    inputs = np.arange(5 * 1 * 2 * 2, dtype=np.float32).reshape(5, 1, 2, 2)
    targets = np.array([[[0, 0], [0, 0]], [[1, 0], [0, 0]], [[1, 1], [0, 2]], [[2, 2], [2, 2]], [[1, 1], [1, 0]]], np.uint8)
    whole = MaskFrames(inputs, targets, window=2)
    part = MaskFrameSubset(inputs, targets, 2, [4, 2])
    assert len(part) == 2 and part.in_channels == 2
    for k, i in enumerate([4, 2]):
        np.testing.assert_array_equal(part[k][0].numpy(), whole[i][0].numpy())
        np.testing.assert_array_equal(part[k][1].numpy(), targets[i])  # sample i ends at frame i
    assert part.class_counts() == (2, 5)  # frame 4: 1 background, 3 moving; frame 2: 1 and 2 (and 1 uncertain)
    with pytest.raises(IndexError):
        part[2]
    with pytest.raises(ZendarError, match=r"sample indices must lie in \[0, 5\)"):
        MaskFrameSubset(inputs, targets, 2, [5])


def test_bench_stops_with_exit_2_when_the_labelled_part_has_too_few_cars(dataset: Path, tmp_path: Path, monkeypatch,
                                                                        capsys) -> None:
    from zendar_baselines.bench import cli

    demanding = dataclasses.replace(get_config("tiny"), min_labelled_cars=1000)
    monkeypatch.setattr(cli, "get_config", lambda name: demanding)
    code = cli.main(["--quick", "--data", str(dataset), "--out", str(tmp_path / "out")])
    stderr = capsys.readouterr().err
    assert code == 2 and "Traceback" not in stderr
    assert "too few labelled cars for labelled_fraction 0.25" in stderr and "at least 1000 per band" in stderr
    assert not (tmp_path / "out" / "rows").exists()  # stopped before any training
