"""Table 1, row 1: the CFAR baseline (paper §4.3).

CA-CFAR peaks of each radar's latest cube at or before a SAR frame (the loader's rule, as in
``examples/end_to_end.py``), then the shared chain (:mod:`zendar_dataset.detection`):
DOA, the SAR static-scene test, DBSCAN clusters, one scored detection per cluster of dynamic points.
A radar whose range-Doppler maps are smaller than the CFAR window (:func:`cfar_misfits`) has no peaks.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from tqdm import tqdm

from zendar_dataset.detection import (
    ChainParams,
    FramePoints,
    RadarCells,
    cfar_cells,
    frame_cube_points,
    frame_detections,
    frame_timestamps,
    to_frame,
)
from zendar_dataset.errors import ZendarError
from zendar_dataset.format import frame_id
from zendar_dataset.format.reader import DatasetIndex, SceneReader, open_dataset
from zendar_dataset.radar.cfar import DEFAULT_GUARD, DEFAULT_TRAIN, window_misfit

from zendar_baselines.fingerprints import dataset_on_worker, task_root

if TYPE_CHECKING:
    from zendar_dataset.cluster import DaskCluster

METHOD = "cfar-sar-dbscan"

Detections = dict[str, list[dict[str, float]]]


@dataclass(frozen=True)
class CfarSceneTask:
    """One scene to predict on a Dask worker (picklable; the worker opens the dataset at ``root``)."""

    root: str
    storage_options: dict = field(hash=False)
    scene_id: str
    params: ChainParams


def cfar_misfits(reader: SceneReader) -> dict[str, str]:
    """The radars of one open scene whose range-Doppler maps the chain's CFAR window does not fit.

    The chain's CFAR (:func:`zendar_dataset.detection.cfar_map`) runs
    :func:`~zendar_dataset.radar.cfar.cfar_2d` with its default window, which needs at least 11 range
    and 13 Doppler cells.

    Returns
    -------
    dict
        Radar -> why, naming the maps' shape and the window; empty when every radar's maps fit.
    """
    misfits = {}
    for radar in reader.sensors("radar"):
        n_range, n_doppler = reader.array(f"radar/{radar}/cube").shape[1:3]
        misfit = window_misfit((n_range, n_doppler))
        if misfit is not None:
            misfits[radar] = (f"range-Doppler maps of {n_range} range x {n_doppler} Doppler cells, smaller than "
                              f"the CFAR window ({DEFAULT_GUARD[0]} guard and {DEFAULT_TRAIN[0]} training range cells, "
                              f"{DEFAULT_GUARD[1]} guard and {DEFAULT_TRAIN[1]} training Doppler cells on each side): {misfit}")
    return misfits


def scene_predictions(reader: SceneReader, params: ChainParams) -> Detections:
    """Frame id -> the CFAR baseline's detections, for every SAR frame of one open scene; the radars
    of :func:`cfar_misfits` have no CFAR peaks, and a scene with no other radar has no detections (the
    chain does not run on it)."""
    misfits = cfar_misfits(reader)
    if len(misfits) == len(reader.sensors("radar")):
        if not reader.sensors("sar"):
            return {}  # a scene's frames are its first SAR stream's: without one it has none
        return {frame_id(reader.scene_id, frame_ns): [] for frame_ns in frame_timestamps(reader).tolist()}
    poses = reader.ego_poses()

    def cells_of(radar: str, k: int, cube: np.ndarray) -> RadarCells:
        if radar in misfits:
            return RadarCells(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
        return cfar_cells(cube, params)

    results: Detections = {}
    for frame_ns, found in frame_cube_points(reader, cells_of, params, poses=poses):
        points = FramePoints.concatenate([to_frame(cube, poses, frame_ns) for cube in found])
        results[frame_id(reader.scene_id, frame_ns)] = frame_detections(points, params)
    return results


def predict_scene(task: CfarSceneTask) -> Detections:
    """A Dask task: :func:`scene_predictions` of ``task``'s scene, on whichever worker runs it."""
    index = dataset_on_worker(task.root, task.storage_options, task.scene_id)
    with index.open_scene(task.scene_id) as reader:
        return scene_predictions(reader, task.params)


def cfar_predictions(
    root: DatasetIndex | str | os.PathLike, split: str, params: ChainParams | None = None, progress: bool = True,
    storage_options: dict | None = None, cluster: DaskCluster | None = None,
) -> dict[str, Any]:
    """The CFAR baseline's predictions for every frame of a split.

    Parameters
    ----------
    root : DatasetIndex, str or path
        Dataset root, or the dataset already opened.
    split : str
        Split to predict (every SAR frame of its scenes, labelled or not).
    params : ChainParams, optional
        The chain's settings (default: the package's, measured once on the demo training split;
        ``zendar-bench`` passes those it fitted on the run's labelled training scenes, see
        :mod:`zendar_baselines.bench.chain_step`).
    progress : bool
        Show a progress bar (over the frames; over the scenes on a cluster).
    storage_options : dict, optional
        fsspec options for a remote root.
    cluster : DaskCluster, optional
        A connected Dask cluster: one task per scene on its workers, which must read the dataset at
        the same path or URL (each task says which host cannot). The predictions are the same,
        in the same order, wherever the scenes ran.

    Returns
    -------
    dict
        The evaluator's predictions document ``{"meta": {"method", "split", "parameters"}, "results":
        {frame_id: [{"x", "y", "score"}]}}``; every frame appears, with an empty list where nothing is
        found, in the split's scene order. Positions are metres in the ego frame at the frame's timestamp.

    Raises
    ------
    ZendarError
        On a cluster: a host that cannot read the dataset, or a scene whose workers died.
    """
    params = ChainParams() if params is None else params
    index = root if isinstance(root, DatasetIndex) else open_dataset(root, storage_options)
    scene_ids = index.scene_ids(split)
    per_scene: dict[str, Detections] = {}
    if cluster is None:
        with tqdm(desc=f"CFAR baseline {split}", unit="frame", disable=not progress) as bar:
            for scene_id in scene_ids:
                with index.open_scene(scene_id) as reader:
                    per_scene[scene_id] = scene_predictions(reader, params)
                bar.update(len(per_scene[scene_id]))
    else:
        tasks = [CfarSceneTask(task_root(index), dict(index.storage_options), scene_id, params) for scene_id in scene_ids]
        with tqdm(total=len(tasks), desc=f"CFAR baseline {split}", unit="scene", disable=not progress) as bar:

            def done(task: CfarSceneTask, detections: Detections) -> None:
                per_scene[task.scene_id] = detections
                bar.update()

            cluster.run(predict_scene, tasks, shared=None, on_done=done, worker_died=lambda task: ZendarError(
                f"{task.scene_id}: the Dask workers predicting it died (killed, out of memory, or their node lost) as "
                "many times as the scheduler allows (distributed.scheduler.allowed-failures)"))
    results = {fid: detections for scene_id in scene_ids for fid, detections in per_scene[scene_id].items()}
    return {"meta": {"method": METHOD, "split": split, "parameters": params.to_json()}, "results": results}
