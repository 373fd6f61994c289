"""Scoring on the test split: the CFAR baseline's and a trained CNN's predictions, scored by the
official evaluator, with the test scenes opened once for every scoring of a run (:class:`ScoringScenes`).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from zendar_dataset.atomic_files import write_json_atomic
from zendar_dataset.cluster import DaskCluster
from zendar_dataset.detection import (
    ChainParams, FramePoints, frame_cube_points, frame_detections, probability_peaks, to_frame,
)
from zendar_dataset.detection.scene import CellsOf
from zendar_dataset.eval import evaluate
from zendar_dataset.eval.report import write_metrics
from zendar_dataset.format import frame_id
from zendar_dataset.format.reader import DatasetIndex, SceneReader

from zendar_baselines.bench.configs import BenchConfig
from zendar_baselines.bench.ranks import SceneShard
from zendar_baselines.classical import cfar_baseline
from zendar_baselines.classical.chain_fit import CellsFor
from zendar_baselines.classical.kept_scenes import KeptScene, KeptScenes
from zendar_baselines.cnn.input_channels import InputChannels, scene_input_maps
from zendar_baselines.fingerprints import dataset_index, dataset_location

#: Bootstrap resamples (over time blocks of the test scenes, :data:`claims.BLOCK_S`) for each row's 95 % interval.
BOOTSTRAP_RESAMPLES = 1000
#: Local peaks of a CNN's probability map at or above this are the chain's points (a floor, not a
#: decision: the cluster scores order the detections, so the precision-recall curve reaches the
#: recall of every peak kept). Measured on the tiny config's validation split, six models (docs/baselines.md,
#: "CNN peaks"): 0.01 reaches at most 0.02 more recall but places 2-5 times the points (23-57 per
#: cube against 6-16); 0.05 and above lose recall (0.5: 0.18-0.28 against 0.36-0.38 at 0.02).
PEAK_FLOOR = 0.02
#: The CNN rows' chain before its fit: a cluster scores its best peak's probability times its
#: dynamic share (a sum of probabilities would rank big diffuse clusters first).
CNN_CHAIN = ChainParams(cluster_score="max")
#: Inference batch (frames); memory only, results do not depend on it.
PREDICT_BATCH = 8


def cfar_predictions(dataset: DatasetIndex | str | os.PathLike, params: ChainParams | None = None,
                     chain_fit: dict[str, Any] | None = None, cluster: DaskCluster | None = None) -> dict[str, Any]:
    """Table 1 row 1 on the test split (``dataset``: its root, or the dataset already opened), with the
    chain's constants ``params`` and the summary of their fit recorded in the meta; ``cluster``: one
    task per scene on a Dask cluster (:func:`zendar_baselines.classical.cfar_baseline.cfar_predictions`)."""
    predictions = cfar_baseline.cfar_predictions(dataset_index(dataset), "test", params, cluster=cluster)
    if chain_fit is not None:
        predictions["meta"]["chain_fit"] = chain_fit
    return predictions


def score_into(out_dir: Path, predictions: dict[str, Any], root: Path) -> None:
    """``predictions.json`` and the official evaluator's ``metrics.json`` (test split, with a bootstrap
    of :data:`BOOTSTRAP_RESAMPLES` over time blocks of :data:`~zendar_baselines.bench.claims.BLOCK_S`)
    in ``out_dir``. The metrics' ``protocol.bootstrap`` records the blocks and their distinct resamples.
    """
    from zendar_baselines.bench.claims import BLOCK_S

    write_json_atomic(out_dir / "predictions.json", predictions)
    metrics = evaluate(out_dir / "predictions.json", str(root), split="test", bootstrap=BOOTSTRAP_RESAMPLES,
                       bootstrap_block_s=BLOCK_S)
    write_metrics(metrics, out_dir)


class ScoringScenes(KeptScenes):
    """The test split's scenes, opened once for many scorings (a context manager; closes them on exit).

    A default run scores 18 CNNs on the same scenes. With ``keep`` and within
    :data:`~zendar_baselines.classical.kept_scenes.KEPT_SCENE_BYTES` (SAR images and log-power maps),
    the SAR magnitudes (with their medians) and the log-power maps read by the first scoring are
    kept for the next; results equal reading the scenes afresh (the same arrays, read once; the maps
    are read-only).
    """

    def __init__(self, dataset: DatasetIndex | str | os.PathLike, *, keep: bool = True) -> None:
        index = dataset_index(dataset)
        super().__init__(index, index.scene_ids("test"), keep=keep, maps_too=True)
        self.root = Path(self.index.root)

    def scene_ids(self) -> list[str]:
        return self.index.scene_ids("test")

    def maps(self, scene: KeptScene, radar: str, channels: InputChannels = InputChannels()) -> np.ndarray:
        """CNN input maps ``[N, C, R, D]`` of one radar of ``scene`` (kept with the scene):
        log power per antenna and the optional ``channels``."""
        key = (radar, channels)
        if key not in scene.maps:
            maps = scene_input_maps(scene.reader, radar, channels)
            maps.flags.writeable = False
            if not self.keep:
                return maps
            scene.maps[key] = maps
        return scene.maps[key]


def load_model(checkpoint: Path, device: str) -> tuple[Any, dict[str, Any]]:
    """A trained model (checked against its manifest) on ``device``, and its architecture record."""
    from zendar_baselines.cnn.checkpoints import load_checkpoint, load_model_state
    from zendar_baselines.cnn.models import build_model

    stored = load_checkpoint(checkpoint)  # SHA-256 against the manifest, once
    architecture = stored["architecture"]
    model = build_model(architecture["name"], architecture["in_channels"], architecture["width_scale"],
                        architecture.get("inputs"))
    load_model_state(model, stored, checkpoint)
    return model.to(device), architecture


def model_inputs(architecture: dict[str, Any]) -> InputChannels:
    """The input channels a checkpoint's model reads (the paper's input when it records none)."""
    return InputChannels.from_json(architecture.get("inputs"))


def cube_probabilities(model, maps: np.ndarray, window: int, device: str) -> np.ndarray:
    """``[N, R, D]`` float32 probability of a moving object for each of a radar's ``N`` cubes.

    ``maps``: the radar's log-power maps ``[N, A, R, D]``. Cube ``k``'s input is the window ending
    at map ``k``, the first map repeated before the scene's start
    (:func:`zendar_baselines.cnn.maps.stack_window`), so every cube gets a prediction.
    """
    from zendar_baselines.cnn.maps import stack_window
    from zendar_baselines.cnn.training import predict_masks

    return predict_masks(model, stack_window(maps, window), PREDICT_BATCH, device)


def peak_cells_of(probability: dict[str, np.ndarray], floor: float = PEAK_FLOOR) -> CellsOf:
    """The chain's cells of a scene's cubes: the peaks of each cube's probability map
    (``probability``: radar -> ``[N, R, D]``, :func:`cube_probabilities`), score = probability."""
    return lambda radar, k, cube: probability_peaks(probability[radar][k], floor)


def model_cells_for(model, window: int, device: str, maps_of: Callable[[SceneReader, str], np.ndarray]) -> CellsFor:
    """For any open scene, the cells of its cubes by ``model``'s peaks (the CNN rows' fit of the chain,
    :mod:`zendar_baselines.classical.chain_fit`); ``maps_of(reader, radar)``: the model's input maps
    ``[N, C, R, D]`` of one radar (e.g. the run's cached :func:`zendar_baselines.bench.steps.scene_maps`)."""

    def cells_for(reader: SceneReader) -> CellsOf:
        return peak_cells_of({radar: cube_probabilities(model, maps_of(reader, radar), window, device)
                              for radar in reader.sensors("radar")})

    return cells_for


def cnn_predictions(root: DatasetIndex | str | os.PathLike, config: BenchConfig, checkpoint: Path, device: str,
                    params: ChainParams | None = None, scenes: ScoringScenes | None = None,
                    chain_fit: dict[str, Any] | None = None, progress: bool = True,
                    shard: SceneShard | None = None) -> dict[str, Any]:
    """A trained model's detections on every test frame, through the CFAR baseline's chain.

    Per radar cube (the first cubes of a scene with their window padded by the first map), the
    peaks of the model's probability map at or above :data:`PEAK_FLOOR` (score = probability) are
    placed by DOA, put to the SAR test with ``params`` (the constants fitted on this model's own
    peaks, whose fit ``chain_fit`` summarises in the meta) and clustered with the other radar's
    points of the frame. ``scenes``: the test scenes shared with other scorings
    (:class:`ScoringScenes`); by default they are opened for this call only. ``progress``: show a
    progress bar over the frames. ``shard``: torchrun's ranks share the test scenes
    (:class:`zendar_baselines.bench.ranks.SceneShard`), and every rank returns every frame's detections.
    """
    model, architecture = load_model(checkpoint, device)
    params = CNN_CHAIN if params is None else params
    window = config.window
    if scenes is not None and scenes.root.resolve() != Path(dataset_location(root)).resolve():
        raise ValueError(f"cnn_predictions: scenes of {scenes.root} given to score {root}")
    with contextlib.ExitStack() as stack:
        if scenes is None:
            scenes = stack.enter_context(ScoringScenes(root, keep=False))
        results = _predict_test_split(model, model_inputs(architecture), scenes, window, params, device,
                                      architecture["name"], progress, shard)
    meta = {"method": f"{architecture['name']} probability peaks + SAR test + DBSCAN", "checkpoint": checkpoint.name,
            "architecture": architecture, "parameters": params.to_json(), "peak_floor": PEAK_FLOOR}
    if chain_fit is not None:
        meta["chain_fit"] = chain_fit
    return {"meta": meta, "results": results}


def _predict_test_split(model, channels: InputChannels, scenes: ScoringScenes, window: int, params: ChainParams,
                        device: str, name: str, progress: bool,
                        shard: SceneShard | None = None) -> dict[str, list[dict[str, float]]]:
    """Per test frame id, the detections of ``model``'s peaks through the chain (see :func:`cnn_predictions`)."""
    per_scene: dict[str, dict[str, list[dict[str, float]]]] = {}
    scene_ids = scenes.scene_ids()
    with tqdm(desc=f"{name} test", unit="frame", disable=not progress) as bar:
        for scene_id in scene_ids if shard is None else shard.mine(scene_ids):
            results = per_scene[scene_id] = {}
            with scenes.opened(scene_id) as scene:
                probability = {radar: cube_probabilities(model, scenes.maps(scene, radar, channels), window, device)
                               for radar in scene.reader.sensors("radar")}
                for frame_ns, found in frame_cube_points(scene.reader, peak_cells_of(probability), params,
                                                         poses=scene.poses, sar=scene.sar):
                    points = FramePoints.concatenate([to_frame(cube, scene.poses, frame_ns) for cube in found])
                    results[frame_id(scene_id, frame_ns)] = frame_detections(points, params)
                    bar.update(1)
    if shard is not None:
        per_scene = shard.gather(per_scene)
    return {fid: detections for scene_id in scene_ids for fid, detections in per_scene[scene_id].items()}
