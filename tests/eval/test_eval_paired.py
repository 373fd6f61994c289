"""Paired bootstrap of AP differences: cases whose answer is known without the code."""

import numpy as np
import pytest

from zendar_dataset.eval import evaluate
from zendar_dataset.eval.bootstrap import resample_weights
from zendar_dataset.eval.evaluate import frame_units, matched_detections
from zendar_dataset.eval.paired import (
    ResampledAP,
    paired_difference,
    resampled_ap,
    too_few_resamples,
    verdict,
)

NS = 1_000_000_000


def _frames(n_scenes=3, n_frames=40):
    """One car at 10 m (near) and one at 40 m (far) in every frame, 10 Hz."""
    return {
        f"s{s}/{k * NS // 10}": [{"x": 10.0, "y": 0.0}, {"x": 40.0, "y": 0.0}]
        for s in range(n_scenes) for k in range(n_frames)
    }


def _perfect(frames):
    return {f: [{"x": c["x"], "y": c["y"], "score": 0.9} for c in cars] for f, cars in frames.items()}


def _clutter_first(frames, every=1):
    """Every car found, but in every ``every``-th frame a false alarm near each car scores above it."""
    results = {}
    for k, (f, cars) in enumerate(frames.items()):
        results[f] = [{"x": c["x"], "y": c["y"], "score": 0.5} for c in cars]
        if k % every == 0:
            results[f] += [{"x": c["x"], "y": 6.0, "score": 0.8} for c in cars]
    return results


def _resampled(frames, results, weights, frame_unit):
    bands = matched_detections({"results": results}, {"frames": frames}).band_detections(frame_unit)
    return {band: resampled_ap(bands[band], weights) for band in ("near", "far")}


@pytest.fixture(scope="module")
def units():
    frames = _frames()
    matched = matched_detections({"results": _perfect(frames)}, {"frames": frames})
    frame_unit, n_units = frame_units(matched.frame_ids, matched.evaluated_frame, 2.0)
    assert n_units == 6  # 3 scenes of 3.9 s: [0, 2) and [2, 3.9] s each
    return frames, frame_unit, resample_weights(n_units, 400, seed=1)


def test_identical_rows_differ_by_exactly_zero_in_every_resample(units):
    frames, frame_unit, weights = units
    results = _clutter_first(frames, every=3)
    a = _resampled(frames, results, weights, frame_unit)
    b = _resampled(frames, results, weights, frame_unit)
    for band in ("near", "far"):
        assert (a[band].resamples == b[band].resamples).all()
        d = paired_difference(a[band], b[band])
        assert (d.difference, d.low, d.high, d.n, d.verdict) == (0.0, 0.0, 0.0, 400, "undecided")


def test_a_row_better_on_every_frame_holds_and_the_reverse_fails(units):
    frames, frame_unit, weights = units
    better = _resampled(frames, _perfect(frames), weights, frame_unit)
    worse = _resampled(frames, _clutter_first(frames), weights, frame_unit)
    # By hand: the perfect row has AP 1; the other ranks one false alarm above each car in every
    # frame, so its precision is 1/2 at every recall: AP 0.5 in every resample.
    assert (better["near"].resamples == 1.0).all() and np.allclose(worse["near"].resamples, 0.5)
    d = paired_difference(better["near"], worse["near"])
    assert d.difference == pytest.approx(0.5) and d.low == pytest.approx(0.5) and d.verdict == "holds"
    assert paired_difference(worse["far"], better["far"]).verdict == "fails"


def test_bands_of_one_row_over_the_same_resamples(units):
    frames, frame_unit, weights = units
    results = _perfect(frames)
    for f in results:  # the far car is missed in every other frame: far AP 0.5, near AP 1
        if int(f.rpartition("/")[2]) // (NS // 10) % 2:
            results[f] = results[f][:1]
    row = _resampled(frames, results, weights, frame_unit)
    assert evaluate({"results": results}, {"frames": frames})["ap"]["far"] == pytest.approx(row["far"].point)
    d = paired_difference(row["near"], row["far"])
    assert d.verdict == "holds" and 0.4 < d.low <= d.difference <= d.high < 0.6


def test_an_interval_around_zero_is_undecided_and_missing_bands_too():
    rng = np.random.default_rng(3)
    noise = rng.normal(0, 0.05, 500)
    a = ResampledAP(0.51, 0.5 + noise)
    b = ResampledAP(0.50, 0.5 - noise[::-1])
    d = paired_difference(a, b)
    assert d.low < 0 < d.high and d.verdict == "undecided" and d.difference == pytest.approx(0.01)
    none = paired_difference(ResampledAP(float("nan"), np.full(500, np.nan)), b)
    assert (none.difference, none.low, none.high, none.n, none.verdict) == (None, None, None, 0, "undecided")
    assert [verdict(0.01, 0.2), verdict(-0.2, -0.01), verdict(-0.1, 0.1), verdict(0.0, 0.3)] == [
        "holds", "fails", "undecided", "undecided"]
    with pytest.raises(ValueError, match="same resamples"):
        paired_difference(a, ResampledAP(0.5, np.zeros(3)))


def test_too_few_units_are_named_in_a_clear_message():
    assert too_few_resamples(5, "x") is None
    message = too_few_resamples(4, "test split")
    assert message.startswith("test split: 4 resampling units give 35 distinct bootstrap resamples, fewer than 100")
    assert too_few_resamples(0, "empty").startswith("empty: 0 resampling units give 0 distinct")
