"""The chain's constants fitted per run and per detector, and a CNN's peaks on every cube of a scene.

Hand-made labelled frames for the fit's arithmetic and refusals; a tiny simulated dataset (2 training
scenes, 1 validation, 1 test) for the cached ``chain_fit`` step, its guard and its fallback.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from torch import nn

from zendar_dataset.detection import ChainParams, FramePoints, frame_cube_points
from zendar_dataset.errors import ZendarError
from zendar_dataset.format.reader import open_dataset
from zendar_dataset.sim.generate import synthesize_dataset

from zendar_baselines.bench import chain_step
from zendar_baselines.bench.configs import get_config
from zendar_baselines.bench.context import RunContext
from zendar_baselines.bench.run_directory import RunDirectory
from zendar_baselines.bench.scoring import cube_probabilities, peak_cells_of
from zendar_baselines.classical.chain_fit import (
    CLUSTER_EPS_GRID_M,
    LabelledFrames,
    cfar_cells_for,
    fit_chain,
    fit_chain_params,
    fit_on_frames,
    labelled_frames,
    point_separation,
)
from zendar_baselines.cnn.maps import log_power_maps
from zendar_baselines.labels.splits import make_split


def _frames(car_sar_db: tuple[float, float], background_sar_db: float, n_frames: int = 4) -> LabelledFrames:
    """One scene of ``n_frames`` frames, each with a labelled car at (20, 0) m whose near face gives
    two points 0.6 m apart, and two background points far from it; the radar at the origin."""
    frames = LabelledFrames({}, {}, {}, {}, {"scene-a": []})
    for k in range(n_frames):
        fid = f"scene-a/{k}"
        frames.points[fid] = FramePoints(
            points_xy=np.array([(18.5, 0.3), (18.5, -0.3), (5.0, 30.0), (40.0, -30.0)]), radar_xy=np.zeros((4, 2)),
            score=np.ones(4), sar_db=np.array([*car_sar_db, background_sar_db, background_sar_db]), dynamic=np.zeros(4, bool),
        )
        frames.labels[fid] = np.array([(20.0, 0.0)])
        frames.on_car[fid] = np.array([True, True, False, False])
        frames.range_m[fid] = np.hypot(*frames.points[fid].points_xy.T)
        frames.scene_frames["scene-a"].append(fid)
    return frames


def test_the_fit_by_hand_threshold_offset_and_radius():
    params, fit = fit_on_frames(_frames((8.0, 9.0), 30.0), ChainParams())
    # 9 dB is the highest threshold that still takes no background point: F1 = 1, Youden's J = 1.
    separation = fit["point_separation"]
    assert (separation["auc"], separation["f1_threshold_db"], separation["youden_threshold_db"], separation["youden_j"]) == (1.0, 9.0, 9.0, 1.0)
    # Cars at 18.5 m (mid), background at 30.4 m (far) and 50 m (beyond): no band holds both kinds.
    assert separation["auc_per_band"] == {"near": None, "mid": None, "far": None}
    assert params.sar.threshold_db == 9.0
    # Dynamic (< 9 dB): the point at (18.5, 0.3) only, which places its cluster; the label lies
    # beyond it along the line of sight by (20 - 18.5, -0.3) . (18.5, 0.3) / |(18.5, 0.3)|.
    expected_offset_m = (1.5 * 18.5 - 0.3 * 0.3) / np.hypot(18.5, 0.3)
    assert params.centre_offset_m == round(expected_offset_m, 2)
    assert fit["ap"]["all"] == 1.0  # every car found, nothing else
    # Every radius gives the same detections: the smallest is kept.
    assert params.cluster_eps_m == CLUSTER_EPS_GRID_M[0]
    assert [entry["ap_all"] for entry in fit["radius_grid"]] == [1.0] * len(CLUSTER_EPS_GRID_M)
    assert fit["frames"] == 4 and fit["points"] == 16 and fit["on_car_points"] == 8


def test_a_fit_without_a_separating_threshold_is_a_clear_error():
    with pytest.raises(ZendarError, match="no SAR threshold separates the CNN points on labelled cars from the others"):
        fit_on_frames(_frames((30.0, 31.0), 10.0), ChainParams(), "CNN", "somewhere")  # cars brighter than the rest
    with pytest.raises(ZendarError, match="8 of 16 points on cars"):
        fit_on_frames(_frames((20.0, 20.0), 20.0), ChainParams())  # no contrast at all


def test_held_out_frames_are_the_last_quarter_of_each_scene():
    frames = _frames((8.0, 9.0), 30.0, n_frames=8)
    frames.scene_frames["scene-b"] = []
    for k in range(2):
        fid = f"scene-b/{k}"
        frames.points[fid], frames.labels[fid], frames.on_car[fid] = (frames.points["scene-a/0"], frames.labels["scene-a/0"],
                                                                      frames.on_car["scene-a/0"])
        frames.scene_frames["scene-b"].append(fid)
    fit, check = frames.held_out()
    assert check.scene_frames == {"scene-a": ["scene-a/6", "scene-a/7"], "scene-b": ["scene-b/1"]}
    assert list(fit.points) == [f"scene-a/{k}" for k in range(6)] + ["scene-b/0"]
    assert not set(fit.points) & set(check.points)


@pytest.fixture(scope="module")
def tiny_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("chain_fit") / "tiny"
    synthesize_dataset(root, "tiny", n_scenes=4, seed=5, split_ratios=(2, 1, 1), progress=False)
    return root


def test_the_fit_step_is_cached_refits_for_another_split_and_is_checked_on_val(tiny_root, tmp_path, capsys):
    config = get_config("tiny")
    context = RunContext.open(tiny_root, config, tmp_path / "out", "cpu")
    directory = RunDirectory(tmp_path / "out", {"config": config.name})
    split = make_split(context.dataset, 0.5, seed=0)
    params, summary, key = chain_step.cfar_chain_step(directory, context, split, "split-key-1")
    assert "reused" not in capsys.readouterr().err
    document = json.loads((tmp_path / "out" / chain_step.CFAR_STEP / chain_step.CHAIN_FIT_FILE).read_text())
    assert document["fitted"]["threshold_db"] == params.sar.threshold_db == summary["threshold_db"]
    assert summary["fit"]["scenes"] == list(split.labelled) and summary["check"]["source"] == "val"
    assert summary["check"]["scenes"] == ["scene-0002"] and 0.0 <= summary["check"]["auc"] <= 1.0
    assert chain_step.read_chain_fit(tmp_path / "out" / chain_step.CFAR_STEP) == (params, summary)

    again = chain_step.cfar_chain_step(directory, context, split, "split-key-1")
    assert "[chain_fit/cfar] reused" in capsys.readouterr().err and again == (params, summary, key)

    other = next(s for s in (make_split(context.dataset, 0.5, seed=k) for k in range(1, 50)) if s.labelled != split.labelled)
    refitted = chain_step.cfar_chain_step(directory, context, other, "split-key-2")
    assert "reused" not in capsys.readouterr().err
    assert refitted[2] != key and refitted[1]["fit"]["scenes"] == list(other.labelled)


def test_the_fit_refuses_the_test_split(tiny_root):
    index = open_dataset(str(tiny_root))
    with pytest.raises(ZendarError, match="never on split 'test'"):
        fit_chain(index, ["scene-0000"], index.scene_ids("test"), cfar_cells_for(ChainParams()), progress=False)
    with pytest.raises(ZendarError, match="never on split 'test'"):
        fit_chain_params(tiny_root, "test", progress=False)


def test_without_validation_scenes_the_fit_is_checked_on_held_out_training_frames(tiny_root, capsys):
    index = open_dataset(str(tiny_root))
    _, summary = fit_chain(index, index.scene_ids("train"), [], cfar_cells_for(ChainParams()), progress=False)
    warning = capsys.readouterr().err
    assert "warning:" in warning and "no labelled validation scene" in warning and "held out of the fit" in warning
    check, fit = summary["check"], summary["fit"]
    assert check["source"] == "held-out training frames" and check["scenes"] == fit["scenes"] == index.scene_ids("train")
    with index.open_scene("scene-0000") as reader:
        n_frames = len(reader.timestamps("sar/" + reader.sensors("sar")[0]))
    # The last quarter (rounded up) of each of the two scenes' frames.
    assert check["frames"] == 2 * -(-n_frames // 4) and fit["frames"] == 2 * n_frames - check["frames"]


class _MeanOfWindow(nn.Module):
    """Logit = the mean of every channel of the window: a model whose output is easy to compute by hand."""

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        return inputs.mean(dim=1, keepdim=True)


def test_every_cube_of_a_scene_gets_the_models_peaks_the_first_ones_included(tiny_root):
    index = open_dataset(str(tiny_root))
    window = 3
    with index.open_scene(index.scene_ids("test")[0]) as reader:
        maps = {radar: log_power_maps(reader.array(f"radar/{radar}/cube")) for radar in reader.sensors("radar")}
        probability = {radar: cube_probabilities(_MeanOfWindow(), m, window, "cpu") for radar, m in maps.items()}
        for radar, m in maps.items():
            assert probability[radar].shape == (m.shape[0], *m.shape[2:])
            # The first cube's window is its own map three times: its mean over antennas.
            np.testing.assert_allclose(probability[radar][0], 1.0 / (1.0 + np.exp(-m[0].mean(axis=0))), rtol=1e-5)
            np.testing.assert_allclose(probability[radar][1], 1.0 / (1.0 + np.exp(-(2 * m[0] + m[1]).mean(axis=0) / 3)), rtol=1e-5)
        cells_of, n_cells = peak_cells_of(probability, floor=0.0), {}

        def recording(radar, k, cube):
            n_cells[radar, k] = len(cells := cells_of(radar, k, cube))
            return cells

        n_frames = 0
        for _, found in frame_cube_points(reader, recording, ChainParams()):
            assert found and all(len(cube) > 0 for cube in found)  # every frame has points to detect from
            n_frames += 1
        assert n_frames == len(reader.timestamps("sar/" + reader.sensors("sar")[0]))
    # Each radar's first cubes (no full window of 3 behind them) have their peaks too.
    assert all(n_cells[radar, k] > 0 for radar in maps for k in (0, 1))


def test_the_fit_reads_the_labelled_segments_alone(tiny_root, monkeypatch):
    """With the semi-supervised split, only frames of labelled segments enter the fit, and no manual
    label outside them is read: labels outside the segments moved far away change nothing."""
    index = open_dataset(str(tiny_root))
    split = make_split(index, 0.5, seed=0, frames_per_segment=3)
    scenes = list(split.labelled)
    whole = labelled_frames(index, scenes, cfar_cells_for(ChainParams()), progress=False)
    segments = labelled_frames(index, scenes, cfar_cells_for(ChainParams()), progress=False, split=split)
    assert 0 < len(segments.points) < len(whole.points)
    for scene_id, frame_ids in segments.scene_frames.items():
        stamps = np.array([int(fid.rsplit("/", 1)[1]) for fid in frame_ids], np.int64)
        assert split.is_labelled(scene_id, stamps).all()
        for fid in frame_ids:
            np.testing.assert_array_equal(segments.labels[fid], whole.labels[fid])
            np.testing.assert_array_equal(segments.on_car[fid], whole.on_car[fid])

    opened = index.open_scene

    def shifted_outside(scene_id, **kwargs):
        reader = opened(scene_id, **kwargs)
        labels = reader.labels()
        outside = ~split.is_labelled(scene_id, labels["timestamp_ns"])
        moved = {name: values.copy() for name, values in labels.items()}
        moved["x"][outside] += 1000.0
        monkeypatch.setattr(reader, "labels", lambda: moved)
        return reader

    monkeypatch.setattr(index, "open_scene", shifted_outside)
    again = labelled_frames(index, scenes, cfar_cells_for(ChainParams()), progress=False, split=split)
    assert again.scene_frames == segments.scene_frames
    for fid in segments.points:
        np.testing.assert_array_equal(again.labels[fid], segments.labels[fid])


class _TwoRanks:
    """Two ranks of one scene loop, played one after the other in this process: rank 1 runs first and
    keeps its parts; rank 0 then gathers its own with them, as ``all_gather_object`` would."""

    def __init__(self) -> None:
        self.parts: dict = {}

    def rank(self, rank: int):
        from zendar_baselines.bench.ranks import SceneShard

        ranks = self

        class Shard(SceneShard):
            def gather(self, parts):
                if self.rank == 1:
                    ranks.parts = dict(parts)
                    return parts
                return {**parts, **ranks.parts}

        return Shard(rank, 2)


def test_ranks_sharing_the_scenes_give_the_frames_of_one_process(tiny_root):
    """Each rank reads every second scene; the gathered frames equal one process's, in its order."""
    index = open_dataset(str(tiny_root))
    scenes = index.scene_ids("train") + index.scene_ids("val")
    assert len(scenes) >= 3
    whole = labelled_frames(index, scenes, cfar_cells_for(ChainParams()), progress=False)
    two = _TwoRanks()
    alone = labelled_frames(index, scenes, cfar_cells_for(ChainParams()), progress=False, shard=two.rank(1))
    assert set(alone.scene_frames) == set(scenes[1::2])
    gathered = labelled_frames(index, scenes, cfar_cells_for(ChainParams()), progress=False, shard=two.rank(0))
    assert list(gathered.scene_frames) == list(whole.scene_frames) and list(gathered.points) == list(whole.points)
    for fid in whole.points:
        np.testing.assert_array_equal(gathered.points[fid].sar_db, whole.points[fid].sar_db)
        np.testing.assert_array_equal(gathered.on_car[fid], whole.on_car[fid])
        np.testing.assert_array_equal(gathered.labels[fid], whole.labels[fid])


def test_a_threshold_by_the_detections_keeps_the_cars_the_points_criterion_would_drop():
    """CNN-like points: every point already moving, cars and clutter alike, the cars' SAR values spread
    over the clutter's. F1 on the points cuts inside the cars' values and drops the car of some
    frames; the threshold chosen by the chain's AP lets every car through."""
    frames = _frames((8.0, 9.0), 30.0, n_frames=4)
    for k, fid in enumerate(frames.points):
        points = frames.points[fid]
        car_db = 40.0 if k % 2 else 8.0  # half the frames' cars read as bright as the background
        frames.points[fid] = FramePoints(points.points_xy, points.radar_xy, points.score,
                                         np.array([car_db, car_db + 1.0, 30.0, 30.0]), points.dynamic)
    by_points, fit_points = fit_on_frames(frames, ChainParams(), "CNN")
    by_detections, fit_detections = fit_on_frames(frames, ChainParams(), "CNN", threshold_by="detections")
    assert fit_points["threshold_by"] == "points" and fit_detections["threshold_by"] == "detections"
    assert fit_points["ap"]["all"] < 1.0 <= fit_detections["ap"]["all"] + 1e-12
    assert by_detections.sar.threshold_db > 41.0  # above every car's value: the test lets them through
    with pytest.raises(ZendarError, match="threshold_by must be one of"):
        fit_on_frames(frames, ChainParams(), threshold_by="votes")


def test_the_detection_grid_computed_once_per_dynamic_set_equals_every_pair_computed_afresh():
    """``fit_on_frames`` clusters each frame once per radius and computes thresholds with the same
    dynamic points once: its choice and its radius grid equal a plain loop over every pair."""
    from dataclasses import replace

    from zendar_baselines.classical.chain_fit import DETECTION_THRESHOLD_GRID_DB, centre_offset_m, chain_ap

    rng = np.random.default_rng(3)
    frames = LabelledFrames({}, {}, {}, {}, {"scene-a": []})
    for k in range(12):
        fid = f"scene-a/{k}"
        cars = rng.uniform((8.0, -20.0), (55.0, 20.0), size=(3, 2))
        car_points = np.concatenate([car + rng.normal(0.0, 0.8, size=(4, 2)) for car in cars])
        clutter = rng.uniform((0.0, -30.0), (60.0, 30.0), size=(20, 2))
        points_xy = np.concatenate([car_points, clutter])
        sar_db = np.concatenate([rng.normal(5.0, 12.0, len(car_points)), rng.normal(30.0, 15.0, len(clutter))])
        sar_db[rng.random(len(sar_db)) < 0.1] = np.nan
        frames.points[fid] = FramePoints(points_xy, np.zeros_like(points_xy), rng.random(len(points_xy)), sar_db,
                                         np.zeros(len(points_xy), bool))
        frames.labels[fid] = cars
        frames.on_car[fid] = np.arange(len(points_xy)) < len(car_points)
        frames.range_m[fid] = np.hypot(*points_xy.T)
        frames.scene_frames["scene-a"].append(fid)
    base = ChainParams(cluster_score="max")
    fitted, fit = fit_on_frames(frames, base, "CNN", threshold_by="detections")
    f1_db = round(2.0 * fit["point_separation"]["f1_threshold_db"]) / 2.0
    plain = []
    ahead = replace(base, ahead_only=True)  # every label lies ahead of the bumper (x >= 8 m): the fit keeps detections there
    for threshold_db in [f1_db] + [t for t in DETECTION_THRESHOLD_GRID_DB.tolist() if t != f1_db]:
        for eps_m in CLUSTER_EPS_GRID_M:
            trial = replace(ahead, sar=replace(base.sar, threshold_db=threshold_db), cluster_eps_m=eps_m)
            offset = centre_offset_m(frames, trial)
            trial = replace(trial, centre_offset_m=0.0 if offset is None else round(offset, 2))
            plain.append((trial, chain_ap(frames, trial)))
    best, best_ap = max(plain, key=lambda entry: -1.0 if entry[1]["all"] is None else entry[1]["all"])
    assert fitted == best and fit["ap"] == best_ap
    assert fit["radius_grid"] == [{"cluster_eps_m": t.cluster_eps_m, "centre_offset_m": t.centre_offset_m, "ap_all": a["all"]}
                                  for t, a in plain if t.sar.threshold_db == best.sar.threshold_db]
    assert len({a["all"] for _, a in plain}) > 5  # the grid's pairs do differ: the test compares something


def _frames_equal(got, expected) -> None:
    assert list(got.scene_frames) == list(expected.scene_frames) and list(got.points) == list(expected.points)
    for fid in expected.points:
        np.testing.assert_array_equal(got.points[fid].sar_db, expected.points[fid].sar_db)
        np.testing.assert_array_equal(got.points[fid].points_xy, expected.points[fid].points_xy)
        np.testing.assert_array_equal(got.on_car[fid], expected.on_car[fid])
        np.testing.assert_array_equal(got.labels[fid], expected.labels[fid])


def test_kept_scenes_give_the_frames_of_fresh_ones_opening_each_scene_once(tiny_root, monkeypatch, tmp_path):
    """Passes over kept scenes (readers, poses, SAR magnitudes kept) give the frames of scenes opened
    afresh; each scene is opened once, the second pass opens none; over the budget every pass opens
    them again."""
    from zendar_baselines.classical import kept_scenes

    index = open_dataset(str(tiny_root))
    scenes = index.scene_ids("train") + index.scene_ids("val")
    fresh = labelled_frames(index, scenes, cfar_cells_for(ChainParams()), progress=False)
    opened = index.open_scene
    opens: list[str] = []

    def counted(scene_id, **kwargs):
        opens.append(scene_id)
        return opened(scene_id, **kwargs)

    monkeypatch.setattr(index, "open_scene", counted)
    with kept_scenes.KeptScenes(index, scenes) as kept:
        first = labelled_frames(index, scenes, cfar_cells_for(ChainParams()), progress=False, scenes=kept)
        n_first = len(opens)
        assert sorted(opens) == sorted(scenes)  # each opened once: its sizes read for the budget, then kept
        second = labelled_frames(index, scenes, cfar_cells_for(ChainParams()), progress=False, scenes=kept)
        assert len(opens) == n_first  # nothing opened again
        with kept.opened(scenes[0]) as scene:
            assert scene.sar._cache  # the magnitudes read by the passes stay
    _frames_equal(first, fresh)
    _frames_equal(second, fresh)

    monkeypatch.setattr(kept_scenes, "KEPT_SCENE_BYTES", 0)
    with kept_scenes.KeptScenes(index, scenes) as over_budget:
        opens.clear()
        again = labelled_frames(index, scenes, cfar_cells_for(ChainParams()), progress=False, scenes=over_budget)
        n_again = len(opens)
        labelled_frames(index, scenes, cfar_cells_for(ChainParams()), progress=False, scenes=over_budget)
        assert not over_budget.keep and len(opens) - n_again == len(scenes)  # every scene opened again
    _frames_equal(again, fresh)

    (tmp_path / "dataset.json").write_bytes((tiny_root / "dataset.json").read_bytes())
    with pytest.raises(ValueError, match="scenes of"):
        labelled_frames(index, scenes, cfar_cells_for(ChainParams()), progress=False,
                        scenes=kept_scenes.KeptScenes(str(tmp_path), []))


def test_a_process_keeps_one_set_of_each_split_s_scenes_until_the_run_closes_them(tiny_root, tmp_path):
    """``RunContext.kept_scenes`` (training and validation) and ``scoring_scenes`` (test) are one
    registry per process: every seed of a dataset gets the same instances, other contexts of the same
    dataset too, and ``close_kept_scenes`` closes both kinds (a later call opens afresh)."""
    from zendar_baselines.bench.context import close_kept_scenes
    from zendar_baselines.bench.scoring import ScoringScenes

    config = get_config("tiny")
    context = RunContext.open(tiny_root, config, tmp_path / "out", "cpu")
    other_run = RunContext.open(tiny_root, config, tmp_path / "other", "cpu")
    kept, scoring = context.kept_scenes(), context.scoring_scenes()
    assert isinstance(scoring, ScoringScenes) and type(kept) is not ScoringScenes
    assert other_run.kept_scenes() is kept and other_run.scoring_scenes() is scoring
    test_scene = scoring.scene_ids()[0]
    with scoring.opened(test_scene) as scene:
        assert scene.reader.scene_id == test_scene
    with kept.opened(open_dataset(str(tiny_root)).scene_ids("train")[0]) as scene:
        held = scene
    close_kept_scenes()
    assert context.kept_scenes() is not kept and context.scoring_scenes() is not scoring
    with kept.opened(held.reader.scene_id) as scene:
        assert scene is not held  # the closed instance opens afresh
    close_kept_scenes()


def test_labels_only_ahead_of_the_bumper_make_the_fit_count_and_detect_only_there():
    """A car beside the ego is never labelled when every label lies ahead of the front bumper: its
    points, dynamic-looking, would count as "others" read dynamic. Then only the points ahead (x > 0)
    are judged, and the fitted chain keeps only detections ahead; with a label beside the ego the
    labels' region is not known to end at the bumper and every point counts."""
    points = FramePoints(
        points_xy=np.array([(10.0, 0.0), (10.5, 0.0), (10.0, 5.0), (12.0, -4.0), (-1.0, 4.0), (0.0, 6.0)]),
        radar_xy=np.zeros((6, 2)), score=np.ones(6), sar_db=np.array([-7.0, -5.0, 30.0, 25.0, -6.0, -4.0]),
        dynamic=np.zeros(6, bool),
    )
    on_car = np.array([True, True, False, False, False, False])

    def frames(labels):
        fid = "s/1000000000"
        return LabelledFrames({fid: points}, {fid: np.array(labels, float)}, {fid: on_car},
                              {fid: np.hypot(*points.points_xy.T)}, {"s": [fid]})

    ahead = frames([[10.0, 0.0]])
    assert ahead.labels_ahead_only
    separation = point_separation(ahead)
    assert separation["auc"] == 1.0 and separation["points_per_band"]["near"] == {"on_car": 2, "other": 2}
    np.testing.assert_array_equal(ahead.point_ahead, [True, True, True, True, False, False])
    params, _ = fit_on_frames(ahead, ChainParams())
    assert params.ahead_only

    beside = frames([[10.0, 0.0], [-1.0, 4.0]])  # a labelled car beside the ego
    assert not beside.labels_ahead_only and not frames(np.zeros((0, 2))).labels_ahead_only
    separation = point_separation(beside)
    assert separation["auc"] == pytest.approx(7 / 8) and separation["points_per_band"]["near"] == {"on_car": 2, "other": 4}
    params, _ = fit_on_frames(beside, ChainParams())
    assert not params.ahead_only
