"""Time-block resampling units: blocks by hand, distinct resamples by enumeration, weights as duplicated frames."""

import itertools
import json
import math
import random
import warnings

import numpy as np
import pytest

from zendar_dataset.cli.eval import main as eval_main
from zendar_dataset.errors import ZendarError
from zendar_dataset.eval import evaluate
from zendar_dataset.eval.bootstrap import (
    distinct_resamples,
    frame_blocks,
    resample_weights,
    resampled_average_precision,
)
from zendar_dataset.eval.evaluate import frame_units, matched_detections
from zendar_dataset.eval.protocol import BAND_NAMES

NS = 1_000_000_000


def test_blocks_cut_each_scene_from_its_first_frame():
    # Scene 0: 60 frames at 10 Hz from t = 5 s (5.9 s long): blocks [0, 2), [2, 4), [4, 5.9] s, the
    # last 1.9 s long (kept). Scene 1: 66 frames (6.5 s): the tail [6, 6.5] s is 0.5 s < 1 s and joins
    # the block before it. The scenes' frames are interleaved and share timestamps.
    t0 = np.arange(60) * NS // 10 + 5 * NS
    t1 = np.arange(66) * NS // 10 + 5 * NS
    scene = np.r_[np.zeros(60, int), np.ones(66, int)]
    stamps = np.r_[t0, t1]
    shuffle = np.random.default_rng(0).permutation(len(scene))
    blocks, n = frame_blocks(scene[shuffle], stamps[shuffle], 2.0)
    unshuffled = np.empty_like(blocks)
    unshuffled[shuffle] = blocks
    assert n == 6
    assert unshuffled[:60].tolist() == [0] * 20 + [1] * 20 + [2] * 20
    assert unshuffled[60:].tolist() == [3] * 20 + [4] * 20 + [5] * 26


def test_a_gap_leaves_no_empty_block_and_a_long_block_is_the_scene():
    stamps = np.array([0, 1, 7, 8]) * NS // 2  # 0, 0.5, 3.5, 4 s: nothing in [2, 3.5)
    blocks, n = frame_blocks(np.zeros(4, int), stamps, 1.0)
    assert blocks.tolist() == [0, 0, 1, 1] and n == 2
    blocks, n = frame_blocks(np.array([2, 2, 7]), np.array([0, NS, 0]), 100.0)
    assert blocks.tolist() == [0, 0, 1] and n == 2
    with pytest.raises(ValueError, match="block_s must be positive"):
        frame_blocks(np.zeros(1, int), np.zeros(1, int), 0.0)


@pytest.mark.parametrize("n", range(0, 7))
def test_distinct_resamples_count_the_multisets(n):
    # Independent: enumerate the multisets of n units drawn n times.
    enumerated = len(set(itertools.combinations_with_replacement(range(n), n))) if n else 0
    assert distinct_resamples(n) == enumerated
    assert distinct_resamples(n) == (math.comb(2 * n - 1, n) if n else 0)


def test_requirement_of_100_distinct_resamples_needs_five_units():
    assert [distinct_resamples(n) >= 100 for n in (2, 3, 4, 5)] == [False, False, False, True]
    assert distinct_resamples(2) == 3 and distinct_resamples(5) == 126 and distinct_resamples(6) == 462


def test_weights_draw_every_multiset_and_each_unit_as_often():
    weights = resample_weights(3, 20_000, seed=4)
    assert weights.shape == (20_000, 3) and (weights.sum(axis=1) == 3).all()
    assert len({tuple(row) for row in weights}) == distinct_resamples(3)  # all 10 appear
    # Each unit is drawn on average once per resample (multinomial(3, 1/3) mean).
    assert np.allclose(weights.mean(axis=0), 1.0, atol=0.03)
    assert (resample_weights(3, 50, seed=4) == weights[:50]).all()


def _drive(n_scenes=3, n_frames=60, seed=2):
    """Scenes of 10 Hz frames with a few cars at every range, noisy detections and clutter."""
    rng = random.Random(seed)
    frames, results = {}, {}
    for s in range(n_scenes):
        for k in range(n_frames):
            frame = f"scene-{s}/{1_600_000_000 * NS + k * NS // 10}"
            cars = [{"x": rng.uniform(2, 55), "y": rng.uniform(-3, 3)} for _ in range(3)]
            frames[frame] = cars
            results[frame] = [
                {"x": c["x"] + rng.gauss(0, 1.4), "y": c["y"], "score": round(rng.random(), 2)} for c in cars
                if rng.random() < 0.8
            ] + [{"x": rng.uniform(2, 55), "y": 8.0, "score": round(rng.random(), 2)}]
    return frames, results


@pytest.mark.parametrize("weights", [(2, 0, 1, 0, 0, 3, 1, 0, 2), (1,) * 9, (0, 0, 0, 0, 9, 0, 0, 0, 0)])
def test_block_weights_equal_duplicated_frames(weights):
    frames, results = _drive()
    matched = matched_detections({"results": results}, {"frames": frames})
    frame_unit, n_units = frame_units(matched.frame_ids, matched.evaluated_frame, 2.0)
    assert n_units == 9
    dup_frames, dup_results = {}, {}
    for frame_id, unit in zip(matched.frame_ids, frame_unit):
        for copy in range(weights[unit]):
            dup_frames[f"{copy}-{frame_id}"] = frames[frame_id]
            dup_results[f"{copy}-{frame_id}"] = results[frame_id]
    duplicated = evaluate({"results": dup_results}, {"frames": dup_frames})
    bands = matched.band_detections(frame_unit)
    for band in BAND_NAMES:
        resampled = resampled_average_precision(bands[band], np.array([weights]))[0]
        if duplicated["ap"][band] is None:
            assert np.isnan(resampled)
        else:
            assert resampled == pytest.approx(duplicated["ap"][band], abs=1e-12)


def test_block_bootstrap_in_metrics_and_a_block_longer_than_scenes_is_the_scene_bootstrap():
    frames, results = _drive()
    blocks = evaluate({"results": results}, {"frames": frames}, bootstrap=300, bootstrap_block_s=2.0)
    assert blocks["protocol"]["bootstrap"] == {
        "unit": "scene_time_block", "interval": "percentile", "confidence": 0.95, "block_s": 2.0,
        "n_units": 9, "distinct_resamples": math.comb(17, 9),
    }
    near = blocks["bootstrap"]["near"]
    assert near["low"] < blocks["ap"]["near"] < near["high"] and near["n"] == 300
    scenes = evaluate({"results": results}, {"frames": frames}, bootstrap=300)
    long_blocks = evaluate({"results": results}, {"frames": frames}, bootstrap=300, bootstrap_block_s=60.0)
    assert long_blocks["bootstrap"] == scenes["bootstrap"]
    assert scenes["protocol"]["bootstrap"] == {"unit": "scene", "interval": "percentile", "confidence": 0.95}


def test_block_bootstrap_refuses_frame_ids_without_timestamps_and_bad_lengths():
    with pytest.raises(ZendarError, match="frame 's/one' has no integer timestamp"):
        evaluate({"results": {"s/one": []}}, {"frames": {"s/one": []}}, bootstrap=5, bootstrap_block_s=1.0)
    for bad in (0, -1.0, float("nan"), "2", True):
        with pytest.raises(ZendarError, match="bootstrap_block_s must be a"):
            evaluate({"results": {"s/1": []}}, {"frames": {"s/1": []}}, bootstrap=5, bootstrap_block_s=bad)


def test_cli_option_and_the_few_resamples_note(tmp_path, capsys):
    frames, results = _drive(n_scenes=2, n_frames=20)
    (tmp_path / "p.json").write_text(json.dumps({"results": results}))
    (tmp_path / "g.json").write_text(json.dumps({"frames": frames}))
    args = [str(tmp_path / "p.json"), "--gt", str(tmp_path / "g.json"), "--bootstrap", "50"]
    assert eval_main(args) == 0
    text = capsys.readouterr().out
    assert "over up to 50 scene resamples" in text and "only 3 distinct resamples of 2 units" in text
    assert eval_main(args + ["--bootstrap-block-s", "0.5", "--out", str(tmp_path / "o")]) == 0
    text = capsys.readouterr().out
    assert "0.5 s time block resamples" in text and "distinct resamples of" not in text
    metrics = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert metrics["protocol"]["bootstrap"]["n_units"] == 8
    with pytest.raises(SystemExit) as exit_info:
        eval_main(args + ["--bootstrap-block-s", "0"])
    assert exit_info.value.code == 2


def test_one_block_is_named_as_a_block_in_the_table():
    from zendar_dataset.eval.report import format_table

    frames = {f"s/{k * NS // 10}": [{"x": 10.0, "y": 0.0}] for k in range(5)}
    results = {f: [{"x": 10.0, "y": 0.0, "score": 0.5}] for f in frames}
    text = format_table(evaluate({"results": results}, {"frames": frames}, bootstrap=10, bootstrap_block_s=5.0))
    assert "over up to 10 5 s time block resamples" in text
    assert "one time block: resampling cannot show any spread" in text and "one scene" not in text


def _reference_block_count(scene, stamps, block_s):
    """Blocks by exact rational arithmetic, one scene at a time (independent of numpy's floats)."""
    from fractions import Fraction

    block_ns = Fraction(block_s) * NS
    n = 0
    for s in set(scene.tolist()):
        elapsed = [int(t) - int(stamps[scene == s].min()) for t in stamps[scene == s]]
        k = [e // block_ns if block_ns > 0 else None for e in elapsed]  # Fraction floor division
        last = max(k)
        if last > 0 and max(elapsed) - min(e for e, b in zip(elapsed, k) if b == last) < block_ns / 2:
            k = [last - 1 if b == last else b for b in k]
        n += len(set(k))
    return n


@pytest.mark.parametrize("block_s", [5e-324, 1e-300, 1e-20, 3e-10, 1e-9, 0.7e-9, 0.013, 0.25, 1.0, 3.0, 1e300])
def test_blocks_match_an_exact_count_for_any_positive_block(block_s):
    rng = np.random.default_rng(7)
    # Two scenes of 10 Hz frames with nanosecond jitter, one with a gap; a third two frames 1 ns apart.
    t0 = np.arange(40) * NS // 10 + rng.integers(0, 1000, 40) + 10**18
    t1 = np.r_[np.arange(20), np.arange(50, 70)] * NS // 10 + rng.integers(0, 1000, 40)
    scene = np.r_[np.zeros(40, int), np.ones(40, int), [2, 2]]
    stamps = np.r_[t0, t1, [5, 6]]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the cast of an infinite block count warned
        blocks, n = frame_blocks(scene, stamps, block_s)
    assert n == _reference_block_count(scene, stamps, block_s)
    assert sorted(set(blocks.tolist())) == list(range(n))
    if block_s <= 0.5e-9:  # every spacing (1 ns or more) spans two blocks: one unit per frame
        assert n == len(scene)


def test_a_block_far_shorter_than_a_frame_gives_one_unit_per_frame_in_metrics(tmp_path, capsys):
    frames = {f"s/{k * NS // 10}": [{"x": 10.0, "y": 0.0}] for k in range(10)}
    results = {f: [{"x": 10.0, "y": 0.0, "score": 0.5}] for f in frames}
    (tmp_path / "p.json").write_text(json.dumps({"results": results}))
    (tmp_path / "g.json").write_text(json.dumps({"frames": frames}))
    args = [str(tmp_path / "p.json"), "--gt", str(tmp_path / "g.json"), "--bootstrap", "10"]
    assert eval_main(args + ["--bootstrap-block-s", "1e-300", "--out", str(tmp_path / "o")]) == 0
    assert json.loads((tmp_path / "o" / "metrics.json").read_text())["protocol"]["bootstrap"]["n_units"] == 10
    assert "RuntimeWarning" not in capsys.readouterr().err


@pytest.mark.parametrize("stamp", ["\u00b2", "\u0663", "9223372036854775808", "1" * 5000])
def test_time_blocks_refuse_timestamps_that_are_not_int64_ascii_digits(stamp):
    frame = f"s/{stamp}"
    with pytest.raises(ZendarError, match="bootstrap over time blocks needs"):
        evaluate({"results": {frame: []}}, {"frames": {frame: []}}, bootstrap=5, bootstrap_block_s=1.0)
