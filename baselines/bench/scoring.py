"""Scoring on the test split: the CFAR baseline's and a trained CNN's predictions, scored by the
official evaluator, with the test scenes opened once for every scoring of a run (:class:`ScoringScenes`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from zendar_dataset.atomic_files import write_json_atomic
from zendar_dataset.detection import (
    ChainParams, FramePoints, RadarCells, frame_cube_points, frame_detections, mask_cells, to_frame,
)
from zendar_dataset.eval import evaluate
from zendar_dataset.eval.report import write_metrics
from zendar_dataset.format import frame_id
from zendar_dataset.format.reader import DatasetIndex, SceneReader
from zendar_dataset.geometry.frames import EgoPoses
from zendar_dataset.sar.frames import SarFrames

from zendar_baselines.bench.configs import BenchConfig
from zendar_baselines.classical import cfar_baseline
from zendar_baselines.fingerprints import dataset_index, dataset_location

#: Bootstrap resamples (over time blocks of the test scenes, :data:`claims.BLOCK_S`) for each row's 95 % interval.
BOOTSTRAP_RESAMPLES = 1000
#: Mask cells at or above this probability are the CNN's detections (the sigmoid's midpoint).
MASK_THRESHOLD = 0.5
#: Inference batch (frames); memory only, results do not depend on it.
PREDICT_BATCH = 8


def cfar_predictions(dataset: DatasetIndex | str | os.PathLike) -> dict[str, Any]:
    """Table 1 row 1 on the test split (``dataset``: its root, or the dataset already opened)."""
    return cfar_baseline.cfar_predictions(dataset_index(dataset), "test")


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


#: Budget for what :class:`ScoringScenes` keeps between scorings: the test split's SAR magnitudes and
#: log-power maps (float32). The demo config's take ~280 MB; the paper config's would not fit, and
#: every scoring then reads them again.
TEST_SCENE_CACHE_BYTES = 1 << 30


@dataclasses.dataclass
class _ScoringScene:
    """One open test scene with what every scoring of it needs."""

    reader: SceneReader
    poses: EgoPoses
    sar: SarFrames
    maps: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)


class ScoringScenes:
    """The test split's scenes, opened once for many scorings (a context manager; closes them on exit).

    A default run scores 18 CNNs on the same scenes. With ``keep`` and within
    :data:`TEST_SCENE_CACHE_BYTES`, the SAR magnitudes (with their medians) and the log-power maps
    read by the first scoring are kept for the next; results equal reading the scenes afresh (the
    same arrays, read once; the maps are read-only).
    """

    def __init__(self, dataset: DatasetIndex | str | os.PathLike, *, keep: bool = True) -> None:
        self.index = dataset_index(dataset)
        self.root = Path(self.index.root)
        self.keep = keep
        self._scenes: dict[str, _ScoringScene] = {}
        self._stack = contextlib.ExitStack()

    def __enter__(self) -> ScoringScenes:
        return self

    def __exit__(self, *exc: Any) -> None:
        self._scenes.clear()
        self._stack.close()

    def scene_ids(self) -> list[str]:
        return self.index.scene_ids("test")

    def _fits(self) -> bool:
        total = 0
        for scene_id in self.scene_ids():
            with self.index.open_scene(scene_id) as reader:
                arrays = [f"sar/{s}/image" for s in reader.sensors("sar")]
                arrays += [f"radar/{r}/cube" for r in reader.sensors("radar")]
                total += sum(4 * int(np.prod(reader.array(a).shape)) for a in arrays)
        return total <= TEST_SCENE_CACHE_BYTES

    @contextlib.contextmanager
    def opened(self, scene_id: str) -> Iterator[_ScoringScene]:
        """The open scene: kept for later scorings when ``keep`` and the split fits the budget,
        else opened for this ``with`` block only."""
        if scene_id in self._scenes:
            yield self._scenes[scene_id]
            return
        if self.keep and not self._scenes and not self._fits():
            self.keep = False
        if self.keep:
            reader = self._stack.enter_context(self.index.open_scene(scene_id))
            self._scenes[scene_id] = _ScoringScene(reader, reader.ego_poses(), SarFrames(reader, keep_frames=None))
            yield self._scenes[scene_id]
            return
        with self.index.open_scene(scene_id) as reader:
            yield _ScoringScene(reader, reader.ego_poses(), SarFrames(reader))

    def maps(self, scene: _ScoringScene, radar: str) -> np.ndarray:
        """Log-power maps ``[N, A, R, D]`` of one radar of ``scene`` (kept with the scene)."""
        from zendar_baselines.cnn.maps import log_power_maps

        if radar not in scene.maps:
            maps = log_power_maps(scene.reader.array(f"radar/{radar}/cube"))
            maps.flags.writeable = False
            if not self.keep:
                return maps
            scene.maps[radar] = maps
        return scene.maps[radar]


def cnn_predictions(root: DatasetIndex | str | os.PathLike, config: BenchConfig, checkpoint: Path, device: str,
                    params: ChainParams | None = None, scenes: ScoringScenes | None = None) -> dict[str, Any]:
    """A trained model's detections on every test frame, through the CFAR baseline's chain.

    Per radar cube with a full window of K maps, the cells the model calls moving (probability ≥
    :data:`MASK_THRESHOLD`, score = probability) are placed by DOA, put to the SAR test and
    clustered with the other radar's points of the frame. ``scenes``: the test scenes shared with
    other scorings (:class:`ScoringScenes`); by default they are opened for this call only.
    """
    from zendar_baselines.cnn.checkpoints import load_checkpoint, load_model_state
    from zendar_baselines.cnn.models import build_model

    stored = load_checkpoint(checkpoint)  # SHA-256 against the manifest, once
    architecture = stored["architecture"]
    model = build_model(architecture["name"], architecture["in_channels"], architecture["width_scale"])
    load_model_state(model, stored, checkpoint)
    model.to(device)
    params = ChainParams() if params is None else params
    window = config.window
    if scenes is not None and scenes.root.resolve() != Path(dataset_location(root)).resolve():
        raise ValueError(f"cnn_predictions: scenes of {scenes.root} given to score {root}")
    with contextlib.ExitStack() as stack:
        if scenes is None:
            scenes = stack.enter_context(ScoringScenes(root, keep=False))
        results = _predict_test_split(model, scenes, window, params, device, architecture["name"])
    meta = {"method": f"{architecture['name']} mask + SAR test + DBSCAN", "checkpoint": checkpoint.name,
            "architecture": architecture, "parameters": params.to_json()}
    return {"meta": meta, "results": results}


def _predict_test_split(model, scenes: ScoringScenes, window: int, params: ChainParams, device: str,
                        name: str) -> dict[str, list[dict[str, float]]]:
    """Per test frame id, the detections of ``model``'s masks through the chain (see :func:`cnn_predictions`)."""
    from zendar_baselines.cnn.maps import stack_window
    from zendar_baselines.cnn.training import predict_masks

    results: dict[str, list[dict[str, float]]] = {}
    with tqdm(desc=f"{name} test", unit="frame") as bar:
        for scene_id in scenes.scene_ids():
            with scenes.opened(scene_id) as scene:
                probability = {}
                for radar in scene.reader.sensors("radar"):
                    maps = scenes.maps(scene, radar)
                    probability[radar] = predict_masks(model, stack_window(maps, window), PREDICT_BATCH, device)

                def cells_of(radar: str, k: int, cube: np.ndarray) -> RadarCells:
                    if k < window - 1:  # no full window yet: the model has no input for this cube
                        return mask_cells(np.zeros(cube.shape[:2]))
                    return mask_cells(probability[radar][k - window + 1], MASK_THRESHOLD)

                for frame_ns, found in frame_cube_points(scene.reader, cells_of, params, poses=scene.poses,
                                                         sar=scene.sar):
                    points = FramePoints.concatenate([to_frame(cube, scene.poses, frame_ns) for cube in found])
                    results[frame_id(scene_id, frame_ns)] = frame_detections(points, params)
                    bar.update(1)
    return results
