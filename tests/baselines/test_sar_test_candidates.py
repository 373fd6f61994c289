"""The SAR-test candidates' measurement reads the chain's points: its "reading minus SNR" column, computed
from the image and the cube on its own, is the chain's SAR value point for point."""

from __future__ import annotations

import numpy as np
import pytest
from zendar_baselines.classical.chain_fit import cfar_cells_for, labelled_frames
from zendar_baselines.classical.sar_test_candidates import (
    CANDIDATES,
    auc_table,
    candidate_values,
    main,
)

from zendar_dataset.detection import ChainParams, SarTestParams
from zendar_dataset.format.reader import open_dataset
from zendar_dataset.sim.generate import synthesize_dataset
from zendar_dataset.sim.profiles import get_profile


@pytest.fixture(scope="module")
def tiny_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("candidates") / "tiny"
    synthesize_dataset(root, get_profile("tiny").with_duration(1.0), n_scenes=1, seed=5, split_ratios=(1, 0, 0), progress=False)
    return root


@pytest.mark.parametrize("search_radius_m", [None, 1.0])
def test_the_chosen_candidate_is_the_chains_value_on_the_chains_points(tiny_root, search_radius_m):
    """With the default SAR window and a wider one (the reading follows the chain's setting)."""
    params = ChainParams() if search_radius_m is None else ChainParams(sar=SarTestParams(search_radius_m=search_radius_m))
    values = candidate_values(tiny_root, "train", params)
    index = open_dataset(str(tiny_root))
    frames = labelled_frames(index, index.scene_ids("train"), cfar_cells_for(params), params, progress=False)
    np.testing.assert_array_equal(values["on_car"], frames.point_on_car)
    np.testing.assert_allclose(values["range_m"], frames.point_range_m)
    np.testing.assert_allclose(values["minus_snr"], frames.sar_db, atol=1e-4)  # float32 images
    assert np.isfinite(frames.sar_db).sum() > 50
    # Every candidate has a value wherever the reading has one (the backgrounds exist where the peak does).
    for name in CANDIDATES:
        assert np.isfinite(values[name]).sum() == np.isfinite(values["reading"]).sum(), name
    assert set(auc_table(values)) == set(CANDIDATES)


def test_a_split_without_scenes_exits_2(tiny_root, capsys):
    assert main([str(tiny_root), "--splits", "val"]) == 2
    assert "has no labelled scene" in capsys.readouterr().err


def test_the_cli_reads_with_the_window_it_is_given(tiny_root, capsys, monkeypatch):
    """``--search-radius-m`` reaches the reading; the default is the chain's window."""
    from zendar_baselines.classical import sar_test_candidates

    used = []
    real = sar_test_candidates.candidate_values
    monkeypatch.setattr(sar_test_candidates, "candidate_values",
                        lambda root, split, params: used.append(params.sar.search_radius_m) or real(root, split, params))
    assert main([str(tiny_root), "--splits", "train"]) == 0
    assert main([str(tiny_root), "--splits", "train", "--search-radius-m", "0.5"]) == 0
    assert used == [SarTestParams().search_radius_m, 0.5]
    default, wide = (block.split("| reading |")[1].split("\n")[0] for block in capsys.readouterr().out.split("split train")[1:])
    assert default != wide  # the wider window reads other pixels


@pytest.mark.parametrize("radius", ["-1", "nan"])
def test_the_cli_refuses_a_bad_window(tiny_root, capsys, radius):
    assert main([str(tiny_root), "--splits", "train", "--search-radius-m", radius]) == 2
    err = capsys.readouterr().err
    assert "search_radius_m" in err and "Traceback" not in err
