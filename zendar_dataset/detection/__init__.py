"""The detection chain, one home for the walkthrough, the fidelity report, the CFAR baseline, the
automatic labels and the CNN post-processing (paper §2.3, §4.3).

Per radar cube::

    range-Doppler cells (CFAR peaks, or a CNN's probability peaks)      cells.py
      -> DOA per cell -> points in the ego frame at the cube's time      locate.py, points.py
      -> SAR static-scene test per point                                 static_scene.py

and per evaluator frame, with every radar's points moved into the frame's ego frame (each point
also moved along its line of sight by its radial velocity over the cube-to-frame time, :func:`to_frame`)::

      -> DBSCAN clusters of all points -> one detection per cluster      clusters.py
         holding dynamic points

A cluster is formed from static and dynamic points alike (paper Fig. 2: a cluster mixing both is
*uncertain*); its detection is placed at the score-weighted centre of its dynamic points and scored
by their summed score (CFAR's SNRs) or their maximum score (a CNN's probabilities, whose sum would
grow with the cluster's size; :attr:`ChainParams.cluster_score`) times the cluster's dynamic share,
so that clusters the SAR test calls wholly dynamic rank above mixed ones.

The radar sees a car's near face (the far side is occluded), so the centre of a cluster lies short
of the car's centre along the line of sight. Each detection is pushed away from the radars by
:attr:`ChainParams.centre_offset_m`, measured on the training split
(``zendar_baselines.classical.chain_fit``).

Modules, bottom up: ``static_scene`` (the SAR value of a point and the static-scene test),
``params`` (:class:`ChainParams`), ``cells``, ``locate``, ``points``, ``clusters``, ``scene`` (the
chain over a scene's frames, with the latest-cube rule of the loader), ``boxes`` (labelled car boxes
and points-in-boxes) and ``classical`` (the walkthrough's simple detector: the same cells and DOA
with the plain Doppler test instead of the SAR test). The batched torch chain of the radar
benchmarks is :mod:`zendar_dataset.radar.batched_chain`.
"""

from zendar_dataset.detection.boxes import ON_CAR_MARGIN_M, LabelBoxes, nearest_label_frame
from zendar_dataset.detection.cells import RadarCells, cfar_cells, cfar_map, cube_power, probability_peaks
from zendar_dataset.detection.clusters import Cluster, cluster_labels, frame_clusters, frame_detections
from zendar_dataset.detection.locate import locate_cells, mount_velocity_ego
from zendar_dataset.detection.params import CFAR_PFA, CLUSTER_EPS_M, CLUSTER_SCORES, DEFAULT_CENTRE_OFFSET_M, ChainParams
from zendar_dataset.detection.points import CubePoints, FramePoints, cell_snr_db, cube_points, to_frame
from zendar_dataset.detection.scene import frame_cube_points, frame_timestamps, latest_cube
from zendar_dataset.detection.static_scene import (
    DEFAULT_MAX_FRAME_GAP_NS,
    DEFAULT_THRESHOLD_DB,
    SarTestParams,
    is_dynamic,
    nearest_frames,
    sar_db_at,
)

__all__ = [
    "CFAR_PFA", "CLUSTER_EPS_M", "CLUSTER_SCORES", "DEFAULT_CENTRE_OFFSET_M", "DEFAULT_MAX_FRAME_GAP_NS", "DEFAULT_THRESHOLD_DB",
    "ON_CAR_MARGIN_M", "ChainParams", "Cluster", "CubePoints", "FramePoints", "LabelBoxes", "RadarCells",
    "SarTestParams", "cell_snr_db", "cfar_cells", "cfar_map", "cluster_labels", "cube_points", "cube_power", "frame_clusters",
    "frame_cube_points", "frame_detections", "frame_timestamps", "is_dynamic", "latest_cube", "locate_cells",
    "mount_velocity_ego", "nearest_frames", "nearest_label_frame", "probability_peaks", "sar_db_at", "to_frame",
]
