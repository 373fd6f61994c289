"""The paper's claims by paired intervals, and distinct labelled cars by band and kind, on cases worked by hand."""

from __future__ import annotations

import numpy as np
import pytest
from zendar_baselines.bench.car_counts import markdown_car_counts
from zendar_baselines.bench.claims import claim_verdicts, markdown_claims
from zendar_baselines.bench.results_table import Row

from zendar_dataset.errors import ZendarError
from zendar_dataset.eval.car_counts import (
    SceneLabels,
    count_distinct_cars,
    track_motion_kinds,
)
from zendar_dataset.eval.evaluate import matched_detections

NS = 1_000_000_000
CARS = [{"x": 10.0, "y": 0.0}, {"x": 20.0, "y": 0.0}, {"x": 45.0, "y": 0.0}]  # near, mid, far


def _frames(n_scenes=3, n_frames=40):
    return {f"s{s}/{k * NS // 10}": CARS for s in range(n_scenes) for k in range(n_frames)}


def _found(frames, keep=lambda k, car: True, clutter=()):
    """Every car ``keep`` allows at score 0.5; in every frame, a false alarm 6 m beside each car index in
    ``clutter``, scored above the cars."""
    results = {}
    for k, (f, cars) in enumerate(frames.items()):
        results[f] = [{**car, "score": 0.5} for i, car in enumerate(cars) if keep(k, i)]
        results[f] += [{"x": cars[i]["x"], "y": 6.0, "score": 0.8} for i in clutter]
    return results


def _run(frames, predictions_by_row, **options):
    rows = [
        Row("cfar", "CFAR", False, False),
        Row("densenet-37-supervised", "zoom-out DenseNet-37", False, True),
        Row("densenet-37-pretrained", "zoom-out DenseNet-37", True, True),
    ]
    matched = {key: [matched_detections({"results": results}, {"frames": frames})
                     for results in (seeds if isinstance(seeds, list) else [seeds])]
               for key, seeds in predictions_by_row.items()}
    return claim_verdicts(rows, matched, n_resamples=300, **options)


def test_verdicts_of_claims_worked_by_hand():
    frames = _frames()
    # CFAR: a false alarm above every near and mid car (AP 0.5 there), far car missed every other frame
    # (AP 0.5): below the CNNs in every band and every resample; flat near = mid = far.
    cfar = _found(frames, keep=lambda k, i: i < 2 or k % 2 == 0, clutter=(0, 1))
    # Both CNNs find every car, nothing else: AP 1 everywhere, identical rows.
    cnn = _found(frames)
    verdicts = _run(frames, {"cfar": cfar, "densenet-37-supervised": cnn, "densenet-37-pretrained": cnn})
    beats = verdicts["cnn_beats_cfar"]
    assert beats["verdict"] == "holds" and len(beats["comparisons"]) == 2 * 3
    first = beats["comparisons"][0]
    assert first["pair"] == "zoom-out DenseNet-37 (supervised only) − CFAR" and first["band"] == "near"
    assert first["difference"] == 0.5 and first["ci95"] == [0.5, 0.5] and first["verdict"] == "holds"
    assert first["n_resamples"] == 300
    helps = verdicts["pretraining_helps"]
    assert helps["verdict"] == "undecided"
    assert [c["verdict"] for c in helps["comparisons"]] == ["undecided"] * 3
    assert all(c["difference"] == 0.0 and c["ci95"] == [0.0, 0.0] for c in helps["comparisons"])
    falls = verdicts["ap_falls_with_range"]
    assert [c["band"] for c in falls["comparisons"][:2]] == ["near − mid", "mid − far"]
    assert falls["verdict"] == "undecided"
    resampling = beats["resampling"]
    assert resampling == {"unit": "scene_time_block", "block_s": 2.0, "n_units": 6, "distinct_resamples": 462,
                          "n_resamples": 300, "seed": 0, "confidence": 0.95, "seeds_compared": "all",
                          "seeds": {"cfar": 1, "densenet-37-supervised": 1, "densenet-37-pretrained": 1}}
    table = markdown_claims(verdicts)
    assert ("| cnn beats cfar | zoom-out DenseNet-37 (supervised only) − CFAR | near | +50.0 [+50.0, +50.0] | holds |"
            in table)
    assert "- pretraining helps (" in table and "**undecided**" in table


def test_a_failing_comparison_fails_its_claim():
    frames = _frames()
    good = _found(frames)
    # The pretrained row ranks a false alarm above its far car: far AP 0.5 < 1, below supervised;
    # and its mid beats its far, while near = mid.
    worse_far = _found(frames, clutter=(2,))
    verdicts = _run(frames, {"cfar": worse_far, "densenet-37-supervised": good, "densenet-37-pretrained": worse_far})
    helps = {c["band"]: c["verdict"] for c in verdicts["pretraining_helps"]["comparisons"]}
    assert helps == {"near": "undecided", "mid": "undecided", "far": "fails"}
    assert verdicts["pretraining_helps"]["verdict"] == "fails"
    falls = [(c["better"], c["band"], c["verdict"]) for c in verdicts["ap_falls_with_range"]["comparisons"]]
    assert ("densenet-37-pretrained", "mid − far", "holds") in falls
    assert ("densenet-37-pretrained", "near − mid", "undecided") in falls


def test_too_few_blocks_give_no_interval_and_different_frames_are_refused():
    frames = _frames(n_scenes=2, n_frames=35)  # 2 scenes of 3.4 s: 4 blocks of 2 s, 35 distinct resamples
    rows = {"cfar": _found(frames), "densenet-37-supervised": _found(frames), "densenet-37-pretrained": _found(frames)}
    few = _run(frames, rows)
    for claim in few.values():
        assert "4 resampling units give 35 distinct bootstrap resamples" in claim["resampling"]["problem"]
        assert claim["verdict"] == "undecided"
        assert all(c["ci95"] == [None, None] and c["n_resamples"] == 0 and c["verdict"] == "undecided"
                   and c["difference"] == 0.0 for c in claim["comparisons"])
    assert "**No intervals**: test split, 2 s time blocks: 4 resampling units" in markdown_claims(few)
    enough = _run(frames, rows, block_s=1.0)["cnn_beats_cfar"]["resampling"]
    assert enough["n_units"] == 6 and "problem" not in enough
    other = _frames(n_scenes=3, n_frames=40)
    matched = {"cfar": [matched_detections({"results": _found(frames)}, {"frames": frames})],
               "x": [matched_detections({"results": _found(other)}, {"frames": other})]}
    with pytest.raises(ZendarError, match="row x: scored on other frames than row cfar"):
        claim_verdicts([Row("cfar", "CFAR", False, False), Row("x", "FPN ResNet-34", False, True)], matched)
    rows = [Row("cfar", "CFAR", False, False), Row("x", "FPN ResNet-34", False, True)]
    with pytest.raises(ZendarError, match="row x: give a list of its seeds' matchings"):
        claim_verdicts(rows, {"cfar": matched["cfar"], "x": matched["cfar"][0]})
    with pytest.raises(ZendarError, match="row x: no seed's predictions"):
        claim_verdicts(rows, {"cfar": matched["cfar"], "x": []})


def _heading(deg):
    return np.radians(np.asarray(deg, dtype=float))


def _kind(car_deg, ego_yaw_rad):
    """The kind of one car labelled over 30 frames with relative headings ``car_deg``."""
    labels = {"timestamp_ns": np.arange(30) * NS // 10, "track_id": np.ones(30, np.int64), "yaw": _heading(car_deg)}
    return track_motion_kinds(labels, ego_yaw_rad)[1]


def test_kinds_of_motion_from_headings():
    steps = np.linspace(0.0, 1.0, 30)
    straight_ego = np.zeros(30)
    assert _kind(5 * np.sin(6 * steps), straight_ego) == "ahead"
    assert _kind(178 + 4 * steps, straight_ego) == "oncoming"  # wraps through ±180°
    assert _kind(-90 + 0 * steps, straight_ego) == "crossing"
    # Out of a cross street into the oncoming lane: course 90° -> 180° over ground.
    assert _kind(90 + 90 * steps, straight_ego) == "turning"
    # A straight crossing car seen while the ego turns 60° left: its relative heading falls from 90° to
    # 30°, its course over ground stays 90°: crossing, not turning.
    ego = _heading(60 * steps)
    assert _kind(90 - 60 * steps, ego) == "crossing"
    # A car ahead following the ego through the same turn turns over ground with it.
    assert _kind(0 * steps, ego) == "turning"


def test_distinct_cars_per_band_count_each_car_of_each_scene_once_and_tabulate():
    # Scene a, track 1: near then mid (two frames each); scene b, track 1 (another car): far;
    # scene a, track 2: always beyond 60 m (in no band).
    a = SceneLabels("a", {"timestamp_ns": np.array([0, 1, 2, 3, 0]) * NS // 10, "track_id": np.array([1, 1, 1, 1, 2]),
                          "x": np.array([5.0, 14.0, 16.0, 29.0, 70.0]), "y": np.zeros(5),
                          "yaw": np.array([0.0, 0.0, 0.0, 0.0, np.pi / 2])}, np.zeros(5))
    b = SceneLabels("b", {"timestamp_ns": np.array([0]), "track_id": np.array([1]), "x": np.array([50.0]),
                          "y": np.zeros(1), "yaw": np.array([np.pi])}, np.zeros(1))
    counts = count_distinct_cars([a, b])
    assert counts.cars == {"near": 1, "mid": 1, "far": 1, "all": 2}
    assert counts.by_kind["all"] == {"ahead": 1, "oncoming": 1}
    assert count_distinct_cars([b]).cars["all"] == 1
    table = markdown_car_counts({"test": counts.to_json()})
    assert "| test | 1 (1/0/0/0) | 1 (1/0/0/0) | 1 (0/1/0/0) | 2 (1/1/0/0) |" in table


def test_a_row_is_the_mean_of_its_seeds_and_their_spread_widens_the_interval():
    """DenseNet-37 supervised: seed 0 finds every car (far AP 1), seed 1 ranks a false alarm above its
    far car (far AP 0.5); CFAR misses the far car every other frame (far AP 0.5 in every resample).
    The row's far AP is 0.75, +0.25 over CFAR; a quarter of the resamples draw seed 1 twice (+0.0), so
    the interval reaches 0: undecided, where the first seed alone would hold."""
    frames = _frames()
    cfar = _found(frames, keep=lambda k, i: i < 2 or k % 2 == 0, clutter=(0, 1))
    good, worse_far = _found(frames), _found(frames, clutter=(2,))
    pooled = _run(frames, {"cfar": cfar, "densenet-37-supervised": [good, worse_far], "densenet-37-pretrained": good})
    far = next(c for c in pooled["cnn_beats_cfar"]["comparisons"]
               if c["better"] == "densenet-37-supervised" and c["band"] == "far")
    assert far["difference"] == 0.25 and far["ci95"] == [0.0, 0.5] and far["verdict"] == "undecided"
    assert pooled["cnn_beats_cfar"]["resampling"]["seeds"]["densenet-37-supervised"] == 2
    first_only = _run(frames, {"cfar": cfar, "densenet-37-supervised": good, "densenet-37-pretrained": good})
    far = next(c for c in first_only["cnn_beats_cfar"]["comparisons"]
               if c["better"] == "densenet-37-supervised" and c["band"] == "far")
    assert far["verdict"] == "holds"


def test_seed_draws_of_a_row_do_not_depend_on_the_other_rows_compared():
    from zendar_baselines.bench.claims import shared_resamples

    frames = _frames()
    seeds = [matched_detections({"results": _found(frames, clutter=clutter)}, {"frames": frames}) for clutter in ((), (2,), (1,))]
    cfar = [matched_detections({"results": _found(frames)}, {"frames": frames})]
    alone, _ = shared_resamples(["row"], {"row": seeds}, n_resamples=200)
    together, _ = shared_resamples(["cfar", "row"], {"cfar": cfar, "row": seeds}, n_resamples=200)
    for band in ("near", "mid", "far"):
        np.testing.assert_array_equal(alone["row"][band].resamples, together["row"][band].resamples)


def test_pooled_over_seeds_by_hand():
    from zendar_dataset.eval.paired import ResampledAP, pooled_over_seeds

    per_seed = [ResampledAP(0.2, np.array([0.1, 0.3, np.nan])), ResampledAP(0.6, np.array([0.5, 0.7, np.nan]))]
    pooled = pooled_over_seeds(per_seed, np.array([[0, 0], [0, 1], [1, 1]]))
    assert pooled.point == pytest.approx(0.4)
    np.testing.assert_allclose(pooled.resamples, [0.1, 0.5, np.nan])
    assert pooled_over_seeds(per_seed[:1], np.zeros((3, 1), np.int64)) is per_seed[0]
    with pytest.raises(ValueError, match="seed draws"):
        pooled_over_seeds(per_seed, np.zeros((3, 3), np.int64))


def test_seed_predictions_are_every_seed_of_a_cnn_row_and_the_one_file_of_cfar(tmp_path):
    from zendar_baselines.bench.claims import seed_predictions

    cnn, cfar = tmp_path / "rows" / "fpn-resnet34-supervised", tmp_path / "rows" / "cfar"
    for k in range(4):  # a leftover fourth seed of an earlier run with more seeds
        (cnn / f"seed-{k}").mkdir(parents=True)
    cfar.mkdir(parents=True)
    assert seed_predictions(cnn, 3) == [cnn / f"seed-{k}" / "predictions.json" for k in range(3)]
    assert seed_predictions(cfar, 3) == [cfar / "predictions.json"]
