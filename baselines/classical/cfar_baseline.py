"""Table 1, row 1: the CFAR baseline (paper §4.3).

CA-CFAR peaks of each radar's latest cube at or before a SAR frame (the loader's rule, as in
``examples/end_to_end.py``), then the shared chain (:mod:`zendar_dataset.detection`):
DOA, the SAR static-scene test, DBSCAN clusters, one scored detection per cluster of dynamic points.
"""

from __future__ import annotations

import os
from typing import Any

from tqdm import tqdm

from zendar_dataset.detection import ChainParams, FramePoints, cfar_cells, frame_cube_points, frame_detections, to_frame
from zendar_dataset.format import frame_id
from zendar_dataset.format.reader import DatasetIndex, open_dataset

METHOD = "cfar-sar-dbscan"


def cfar_predictions(
    root: DatasetIndex | str | os.PathLike, split: str, params: ChainParams | None = None, progress: bool = True,
    storage_options: dict | None = None,
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
        Show a progress bar over the frames.
    storage_options : dict, optional
        fsspec options for a remote root.

    Returns
    -------
    dict
        The evaluator's predictions document ``{"meta": {"method", "split", "parameters"}, "results":
        {frame_id: [{"x", "y", "score"}]}}``; every frame appears, with an empty list where nothing is
        found. Positions are metres in the ego frame at the frame's timestamp.
    """
    params = ChainParams() if params is None else params
    index = root if isinstance(root, DatasetIndex) else open_dataset(root, storage_options)
    scene_ids = index.scene_ids(split)
    results: dict[str, list[dict[str, float]]] = {}
    with tqdm(desc=f"CFAR baseline {split}", unit="frame", disable=not progress) as bar:
        for scene_id in scene_ids:
            with index.open_scene(scene_id) as reader:
                poses = reader.ego_poses()
                for frame_ns, found in frame_cube_points(reader, lambda radar, k, cube: cfar_cells(cube, params), params, poses=poses):
                    points = FramePoints.concatenate([to_frame(cube, poses, frame_ns) for cube in found])
                    results[frame_id(scene_id, frame_ns)] = frame_detections(points, params)
                    bar.update(1)
    return {"meta": {"method": METHOD, "split": split, "parameters": params.to_json()}, "results": results}
