"""The chain over a scene: per frame, each radar's latest cube at or before it, placed and SAR-tested."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np

from zendar_dataset.detection.cells import RadarCells
from zendar_dataset.detection.params import ChainParams
from zendar_dataset.detection.points import CubePoints, cube_points
from zendar_dataset.format.reader import SceneReader
from zendar_dataset.geometry.frames import EgoPoses
from zendar_dataset.sar.frames import SarFrames
from zendar_dataset.sync import latest_at_or_before, resolve_reference

#: ``cells_of(radar, cube_index, cube) -> RadarCells``: the cells of one cube ``[R, D, A]`` that enter the chain.
CellsOf = Callable[[str, int, np.ndarray], RadarCells]


def latest_cube(cube_timestamps_ns: np.ndarray, frame_ns: int) -> int | None:
    """Index of the latest cube at or before ``frame_ns`` (the loader's rule,
    :func:`zendar_dataset.sync.latest_at_or_before`), or None."""
    k = int(latest_at_or_before(cube_timestamps_ns, int(frame_ns)))
    return k if k >= 0 else None


def frame_timestamps(reader: SceneReader) -> np.ndarray:
    """``[F]`` int64 the scene's frames: its first SAR stream's timestamps (docs/format.md)."""
    return reader.timestamps(resolve_reference(reader, "sar"))


def frame_cube_points(
    reader: SceneReader, cells_of: CellsOf, params: ChainParams | None = None, *,
    poses: EgoPoses | None = None, sar: SarFrames | None = None,
) -> Iterator[tuple[int, list[CubePoints]]]:
    """Per frame of a scene, each radar's latest cube at or before it, its cells placed and SAR-tested.

    Parameters
    ----------
    reader : SceneReader
        The scene.
    cells_of : callable
        ``cells_of(radar, cube_index, cube) -> RadarCells``: the cells of a cube ``[R, D, A]``
        (e.g. ``lambda radar, k, cube: cfar_cells(cube, params)``).
    params : ChainParams, optional
        SAR test settings.
    poses, sar : optional
        The scene's ego poses and SAR images when already built.

    Yields
    ------
    frame_ns : int
        The frame's timestamp.
    points : list of CubePoints
        One per radar with a cube at or before the frame (a cube shared by consecutive frames is
        processed once).
    """
    params = ChainParams() if params is None else params
    poses = reader.ego_poses() if poses is None else poses
    sar = SarFrames(reader) if sar is None else sar
    radars = reader.sensors("radar")
    cube_times = {radar: reader.timestamps(f"radar/{radar}") for radar in radars}
    cubes = {radar: reader.array(f"radar/{radar}/cube") for radar in radars}
    calibration = reader.calibration.sensors
    last: dict[str, tuple[int, CubePoints]] = {}
    for frame_ns in frame_timestamps(reader).tolist():
        found = []
        for radar in radars:
            k = latest_cube(cube_times[radar], frame_ns)
            if k is None:
                continue
            if radar not in last or last[radar][0] != k:
                cube = np.asarray(cubes[radar][k])
                cells = cells_of(radar, k, cube)
                last[radar] = (k, cube_points(cube, cells, int(cube_times[radar][k]), calibration[radar], poses, sar, params))
            found.append(last[radar][1])
        yield int(frame_ns), found
