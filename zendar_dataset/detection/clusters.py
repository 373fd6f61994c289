"""Clusters of a frame's points (DBSCAN with one sample) and one detection per cluster."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from zendar_dataset.detection.params import CLUSTER_EPS_M, ChainParams
from zendar_dataset.detection.points import FramePoints


def cluster_labels(points_xy: np.ndarray, eps_m: float = CLUSTER_EPS_M) -> np.ndarray:
    """``[N]`` int DBSCAN cluster of each point ``[N, 2]`` (metres), every point in one (min_samples=1).

    With one sample per core point, DBSCAN's clusters are the connected components of the graph
    joining points at most ``eps_m`` apart, numbered in order of their first point, as
    ``sklearn.cluster.DBSCAN(eps=eps_m, min_samples=1)`` numbers them; a k-d tree finds the pairs
    (a few times faster than DBSCAN's set-up for the hundreds of points of a frame).
    """
    points_xy = np.asarray(points_xy, np.float64)
    n = len(points_xy)
    if n == 0:
        return np.zeros(0, np.int64)
    pairs = cKDTree(points_xy).query_pairs(eps_m, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)[1].astype(np.int64)


@dataclass(frozen=True)
class Cluster:
    """One DBSCAN cluster of a frame's points that holds dynamic points, before the centre correction.

    Attributes
    ----------
    centre_xy : numpy.ndarray
        ``[2]`` float64 metres, score-weighted centre of the dynamic members.
    radar_xy : numpy.ndarray
        ``[2]`` float64 metres, score-weighted position of the radars that saw them.
    score : float
        Summed or maximum score of the dynamic members (:attr:`ChainParams.cluster_score`) times
        the dynamic share.
    n_points, n_dynamic : int
        Members, and members the SAR test calls dynamic.
    """

    centre_xy: np.ndarray
    radar_xy: np.ndarray
    score: float
    n_points: int
    n_dynamic: int

    def corrected_centre(self, offset_m: float) -> np.ndarray:
        """``[2]`` the centre moved ``offset_m`` along the line of sight away from the radars."""
        line_of_sight = self.centre_xy - self.radar_xy
        distance = float(np.hypot(*line_of_sight))
        return self.centre_xy + offset_m * line_of_sight / distance if distance > 0 else self.centre_xy


def frame_clusters(points: FramePoints, params: ChainParams | None = None,
                   labels: np.ndarray | None = None) -> list[Cluster]:
    """DBSCAN over all of a frame's points; the clusters holding dynamic points (module docstring).

    Parameters
    ----------
    points : FramePoints
        Every radar's points of the frame (:meth:`FramePoints.concatenate` of :func:`to_frame`).
    params : ChainParams, optional
        ``cluster_eps_m`` and ``cluster_score``.
    labels : numpy.ndarray, optional
        ``[N]`` int :func:`cluster_labels` of ``points.points_xy`` at ``params.cluster_eps_m``, when
        already known: they do not depend on the SAR test, so a fit trying many thresholds clusters
        each frame once per radius.
    """
    params = ChainParams() if params is None else params
    if not np.any(points.dynamic):
        return []
    labels = cluster_labels(points.points_xy, params.cluster_eps_m) if labels is None else labels
    n_clusters = int(labels.max()) + 1
    moving = points.dynamic
    n_points = np.bincount(labels, minlength=n_clusters)
    n_dynamic = np.bincount(labels[moving], minlength=n_clusters)
    summed = np.bincount(labels[moving], weights=points.score[moving], minlength=n_clusters)
    if params.cluster_score == "max":
        score = np.full(n_clusters, -np.inf)
        np.maximum.at(score, labels[moving], points.score[moving])
    else:
        score = summed
    # Placement needs positive finite weights: a cluster whose scores are not falls back to equal ones.
    finite = np.isfinite(points.score[moving])
    usable = (np.bincount(labels[moving], weights=~finite, minlength=n_clusters) == 0) & (summed > 0)
    weights = np.where(usable[labels[moving]], np.where(finite, points.score[moving], 0.0), 1.0)
    total = np.bincount(labels[moving], weights=weights, minlength=n_clusters)
    centre = np.stack([np.bincount(labels[moving], weights=weights * points.points_xy[moving, axis], minlength=n_clusters)
                       for axis in (0, 1)], axis=1)
    radar = np.stack([np.bincount(labels[moving], weights=weights * points.radar_xy[moving, axis], minlength=n_clusters)
                      for axis in (0, 1)], axis=1)
    return [
        Cluster(centre[c] / total[c], radar[c] / total[c], float(score[c] * n_dynamic[c] / n_points[c]), int(n_points[c]), int(n_dynamic[c]))
        for c in np.flatnonzero(n_dynamic).tolist()
    ]


def frame_detections(points: FramePoints, params: ChainParams | None = None,
                     labels: np.ndarray | None = None) -> list[dict[str, float]]:
    """One scored detection per cluster holding dynamic points, its centre corrected for occlusion.

    Parameters
    ----------
    points : FramePoints
        Every radar's points of the frame.
    params : ChainParams, optional
        ``cluster_eps_m``, ``centre_offset_m`` and ``ahead_only`` (then a detection whose corrected
        centre is not ahead of the front bumper, x <= 0, is dropped).
    labels : numpy.ndarray, optional
        The points' cluster labels when already known (:func:`frame_clusters`).

    Returns
    -------
    list of dict
        ``{"x", "y", "score"}`` in the points' ego frame, metres; the evaluator's format.
    """
    params = ChainParams() if params is None else params
    detections = []
    for cluster in frame_clusters(points, params, labels):
        x, y = cluster.corrected_centre(params.centre_offset_m)
        if x > 0.0 or not params.ahead_only:
            detections.append({"x": float(x), "y": float(y), "score": cluster.score})
    return detections
