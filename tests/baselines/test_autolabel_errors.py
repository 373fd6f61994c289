"""``python -m zendar_baselines.labels.autolabel_errors``: the error tables count what they say, and the
points they read are the automatic labels' own."""

from __future__ import annotations

import numpy as np
import pytest

from zendar_dataset.sim.generate import synthesize_dataset
from zendar_dataset.sim.profiles import get_profile

from zendar_baselines.labels import autolabel_errors
from zendar_baselines.labels.mask_classes import BACKGROUND, MOVING, UNCERTAIN
from zendar_baselines.labels.masks import MaskParams
from zendar_baselines.labels.quality import QUALITY_REFERENCE


def test_the_report_counts_each_kind_of_point_in_its_band():
    table = {  # near: 3 called moving (1 on a car, 1 reference-uncertain, 1 off: a ghost alone 7 m from a box)
        "range_m": np.array([5.0, 6.0, 7.0, 8.0, 20.0, 20.0, 40.0]),
        "reference": np.array([MOVING, UNCERTAIN, BACKGROUND, MOVING, BACKGROUND, BACKGROUND, MOVING]),
        "moving": np.array([True, True, True, False, True, True, False]),
        "dynamic": np.array([True, True, True, False, True, True, True]),
        "residual_mps": np.array([5.0, 0.0, -4.0, 5.0, 0.2, 3.0, 8.0]),
        "cluster_size": np.array([2, 2, 1, 3, 2, 2, 1]),
        "score": np.array([5e3, 10.0, 50.0, 50.0, 20.0, 30.0, 2e4]),
        "box_distance_m": np.array([0.5, 2.0, 7.0, 1.0, 10.0, 12.0, 0.3]),
    }
    report = autolabel_errors.error_report(table).splitlines()
    assert "| near | 3 | 1 | 1 | 1 | 1 | 1 | 7.0 |" in report
    assert "| mid | 2 | 0 | 0 | 2 | 1 | 0 | 11.0 |" in report
    assert "| far | 0 | 0 | 0 | 0 | 0 | 0 | nan |" in report
    # near's car points: one weak (score 50, read static) and one strong (5e3, read dynamic)
    assert "| near | [0, 100) | 1 | 0% |" in report and "| near | [1000, 10000) | 1 | 100% |" in report
    assert "| far | [10000, inf) | 1 | 100% |" in report and "| mid | [0, 100) | 0 | - |" in report


@pytest.fixture(scope="module")
def labelled(tmp_path_factory):
    root = tmp_path_factory.mktemp("errors") / "data"
    synthesize_dataset(root, profile=get_profile("tiny").with_duration(0.5), n_scenes=3, progress=False)
    return root


def test_the_points_are_the_automatic_labels_seeds_read_against_the_reference(labelled):
    table = autolabel_errors.point_table(str(labelled), "train", MaskParams(), QUALITY_REFERENCE)
    n = table["range_m"].size
    assert n > 0 and all(column.shape == (n,) for column in table.values())
    # A moving seed is a point the SAR test calls dynamic, in a cluster of dynamic points only.
    assert np.all(table["dynamic"][table["moving"]])
    assert table["moving"].any() and (table["reference"] == MOVING).any()
    # A higher threshold only adds dynamic points, so every all-dynamic cluster stays one.
    higher = autolabel_errors.point_table(str(labelled), "train", MaskParams().with_sar_threshold(1e3), QUALITY_REFERENCE)
    np.testing.assert_array_equal(higher["range_m"], table["range_m"])
    assert np.all(higher["dynamic"] >= table["dynamic"]) and np.all(higher["moving"] >= table["moving"])
    assert higher["moving"].sum() > table["moving"].sum()


def test_an_unknown_split_or_one_without_labels_is_a_clear_error(labelled, tmp_path, capsys):
    assert autolabel_errors.main([str(labelled), "--split", "nosuch"]) == 2
    assert "found unknown split 'nosuch'" in capsys.readouterr().err
    withheld = tmp_path / "withheld"
    synthesize_dataset(withheld, profile=get_profile("tiny").with_duration(0.5), n_scenes=5, withhold_test_labels=True,
                       progress=False)
    assert autolabel_errors.main([str(withheld), "--split", "test"]) == 2
    assert "split 'test' has no scene with labels to read the automatic labels against" in capsys.readouterr().err
