"""How well candidate SAR static-scene values separate on-car from other CFAR points, per range band.

    python -m zendar_baselines.classical.sar_test_candidates ROOT [--splits train,val]

The measurement behind the choice of :func:`zendar_dataset.detection.static_scene.sar_db_at`
(docs/baselines.md, "The SAR static-scene test"). The points are the chain's CFAR points of every
labelled frame, on a car when inside a labelled box moved to the cube's time and grown by
:data:`zendar_dataset.detection.boxes.ON_CAR_MARGIN_M`, banded by their range from the ego origin
in the frame, exactly as :func:`zendar_baselines.classical.chain_fit.labelled_frames` takes them.
Every candidate starts from the point's *reading*: the brightest SAR pixel within the chain's
``search_radius_m`` (:attr:`zendar_dataset.detection.SarTestParams.search_radius_m`), in dB over the
image's median, in the SAR sensor whose reading is brightest. Candidates (dB; low says "on a car"):

- ``reading``: the reading alone (the absolute test);
- ``local_{1,2,4}m``: the reading over the median of the square window of that half-width around
  the point, same image (a local background);
- ``same_range``: the reading over the median of the image's pixels in the same
  :data:`RANGE_RING_M` ring of range from the radar; ``same_range_local``: over the median of the
  4 m window's pixels within :data:`RANGE_RING_M` of the point's range;
- ``minus_power``, ``minus_snr``: the reading minus the point's range-Doppler power (antenna-summed,
  dB) or SNR (over the CA-CFAR noise estimate, dB): the value of ``sar_db_at``;
- ``local_4m_minus_power``, ``local_4m_minus_snr``, ``same_range_minus_snr``: combinations.

Points the chain leaves unjudged because they lie in the radar's shadow
(:mod:`zendar_dataset.sar.shadow`) are left out of every candidate, and only points ahead of the
ego's front bumper are counted, where the labels cover every car (as the chain fit counts them).

Prints a markdown table of ROC AUC per band and overall for each split.
"""

from __future__ import annotations

import argparse
import itertools
import os
import sys

import numpy as np
from sklearn.metrics import roc_auc_score

from zendar_dataset.cli.common import run_cli
from zendar_dataset.detection import (
    ON_CAR_MARGIN_M,
    ChainParams,
    LabelBoxes,
    SarTestParams,
    cfar_map,
    cube_power,
    frame_cube_points,
    to_frame,
)
from zendar_dataset.detection.static_scene import nearest_frames
from zendar_dataset.errors import ZendarError
from zendar_dataset.eval.protocol import ALL_BAND, BANDS_M, RANGE_BANDS
from zendar_dataset.format.reader import open_dataset
from zendar_dataset.geometry.frames import ego_T_sensor
from zendar_dataset.sar.frames import SAR_SEARCH_RADIUS_M, SarFrames

LOCAL_HALF_WIDTHS_M = (1.0, 2.0, 4.0)
RANGE_RING_M = 0.5
CANDIDATES = (
    "reading", "local_1m", "local_2m", "local_4m", "same_range", "same_range_local", "minus_power", "minus_snr",
    "local_4m_minus_power", "local_4m_minus_snr", "same_range_minus_snr",
)


class _ImageStatistics:
    """Per SAR frame: the peak and background magnitudes around points, and each pixel's range from the radar."""

    def __init__(self, sar: SarFrames, radar_ecef, search_radius_m: float) -> None:
        self.sar, self.radar_ecef, self.search_radius_m, self._rings = sar, radar_ecef, search_radius_m, {}

    def _range_rings(self, sensor: str, frame: int) -> tuple[np.ndarray, np.ndarray]:
        if (sensor, frame) not in self._rings:
            magnitude, _ = self.sar.magnitude(sensor, frame)
            rows, cols = np.indices(magnitude.shape)
            pixels = self.sar.origin[sensor][frame] + rows[..., None] * self.sar.di[sensor][frame] + cols[..., None] * self.sar.dj[sensor][frame]
            range_m = np.linalg.norm(pixels - self.radar_ecef(sensor, int(self.sar.timestamps[sensor][frame])), axis=-1)
            ring = (range_m / RANGE_RING_M).astype(np.int64)
            order = np.argsort(ring, axis=None)
            sorted_ring, sorted_magnitude = ring.ravel()[order], magnitude.ravel()[order]
            bounds = np.searchsorted(sorted_ring, np.arange(ring.max() + 2))
            median = np.array([np.median(sorted_magnitude[a:b]) if b > a else np.nan for a, b in itertools.pairwise(bounds)])
            self._rings = {(sensor, frame): (range_m, median)}
        return self._rings[(sensor, frame)]

    def read(self, sensor: str, frame: int, points_ecef: np.ndarray) -> dict[str, np.ndarray]:
        """``[P]`` dB over the image's median: the peak and each background, NaN outside the image."""
        ij, inside = self.sar.pixels(sensor, frame, points_ecef)
        out = {name: np.full(len(points_ecef), np.nan) for name in ("peak", "same_range", "same_range_local", *self._local_names())}
        if not inside.any():
            return out
        magnitude, floor = self.sar.magnitude(sensor, frame)
        step = float(np.linalg.norm(self.sar.di[sensor][frame]))
        centre = np.rint(ij[inside]).astype(np.int64)

        def window(half_width_m: float) -> tuple[np.ndarray, np.ndarray]:
            offsets = np.arange(-round(half_width_m / step), round(half_width_m / step) + 1)
            rows = np.clip(centre[:, 0, None, None] + offsets[None, :, None], 0, magnitude.shape[0] - 1)
            cols = np.clip(centre[:, 1, None, None] + offsets[None, None, :], 0, magnitude.shape[1] - 1)
            rows, cols = np.broadcast_arrays(rows, cols)
            return rows.reshape(len(centre), -1), cols.reshape(len(centre), -1)

        def to_db(values: np.ndarray) -> np.ndarray:
            return 20.0 * np.log10(np.maximum(values, 1e-30) / floor)

        rows, cols = window(self.search_radius_m)
        out["peak"][inside] = to_db(magnitude[rows, cols].max(axis=1))
        for name, half_width_m in zip(self._local_names(), LOCAL_HALF_WIDTHS_M):
            rows, cols = window(half_width_m)
            out[name][inside] = to_db(np.median(magnitude[rows, cols], axis=1))
        range_m, ring_median = self._range_rings(sensor, frame)
        point_range_m = np.linalg.norm(points_ecef[inside] - self.radar_ecef(sensor, int(self.sar.timestamps[sensor][frame])), axis=1)
        ring = np.clip((point_range_m / RANGE_RING_M).astype(np.int64), 0, ring_median.size - 1)
        out["same_range"][inside] = to_db(ring_median[ring])
        rows, cols = window(LOCAL_HALF_WIDTHS_M[-1])
        near_ring = np.where(np.abs(range_m[rows, cols] - point_range_m[:, None]) < RANGE_RING_M, magnitude[rows, cols], np.nan)
        out["same_range_local"][inside] = to_db(np.nanmedian(near_ring, axis=1))
        return out

    @staticmethod
    def _local_names() -> tuple[str, ...]:
        return tuple(f"local_{half_width_m:g}m" for half_width_m in LOCAL_HALF_WIDTHS_M)


def candidate_values(root: str | os.PathLike, split: str, params: ChainParams | None = None) -> dict[str, np.ndarray]:
    """Every candidate's value, ``on_car`` and ``range_m`` of every CFAR point of the split's labelled frames.

    Returns
    -------
    dict of str to numpy.ndarray
        ``[P]`` arrays: each of :data:`CANDIDATES` (float64 dB), ``on_car`` (bool), ``range_m`` (float64),
        ``ahead`` (bool: ahead of the ego's front bumper, where the labels cover every car; the AUCs
        count only these points, as the chain fit does).
    """
    params = ChainParams() if params is None else params
    index = open_dataset(root)
    columns: dict[str, list[np.ndarray]] = {name: [] for name in (*CANDIDATES, "on_car", "range_m", "ahead")}
    for scene_id in index.scene_ids(split):
        with index.open_scene(scene_id) as reader:
            if reader.labels() is not None:
                _scene_candidates(reader, params, columns)
    if not columns["on_car"]:
        raise ZendarError(f"{root}: split {split!r} has no labelled scene")
    return {name: np.concatenate(values) for name, values in columns.items()}


def _scene_candidates(reader, params: ChainParams, columns: dict[str, list[np.ndarray]]) -> None:
    """Append one labelled scene's points to ``columns`` (:func:`candidate_values`)."""
    labels, poses, sar = reader.labels(), reader.ego_poses(), SarFrames(reader)
    mounts = {sensor: ego_T_sensor(reader.calibration.sensors[sensor]).translation for sensor in sar.sensors}
    statistics = _ImageStatistics(sar, lambda sensor, t_ns: poses.ego_to_ecef(np.asarray(mounts[sensor])[None], t_ns)[0],
                                  params.sar.search_radius_m)
    maps_of: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}  # a cube's power and CA noise maps

    def cells_of(radar, k, cube):
        power = cube_power(cube)
        cells, noise = cfar_map(power, params)
        mount = ego_T_sensor(reader.calibration.sensors[radar]).translation
        maps_of[_cube_key(int(reader.timestamps(f"radar/{radar}")[k]), mount)] = (power, noise)
        return cells

    per_cube: dict[tuple, dict[str, np.ndarray]] = {}
    for frame_ns, found in frame_cube_points(reader, cells_of, params, poses=poses, sar=sar):
        boxes = LabelBoxes.of_frame(labels, frame_ns)
        for cube in found:
            key = _cube_key(cube.timestamp_ns, cube.radar_ego)
            if key not in per_cube:
                per_cube[key] = _cube_candidates(cube, statistics, maps_of.pop(key), params)
            for name, values in per_cube[key].items():
                columns[name].append(values)
            columns["on_car"].append(boxes.moved_to(cube.timestamp_ns, poses).contains(cube.points_ego[:, :2], ON_CAR_MARGIN_M).any(axis=1))
            in_frame = to_frame(cube, poses, frame_ns).points_xy
            columns["range_m"].append(np.hypot(*in_frame.T))
            columns["ahead"].append(in_frame[:, 0] > 0.0)


def _cube_key(timestamp_ns: int, radar_ego) -> tuple:
    """A cube of a scene: its time and its radar's mount (two radars may share a timestamp)."""
    return (int(timestamp_ns), *np.round(np.asarray(radar_ego, np.float64), 6).tolist())


def _cube_candidates(cube, statistics: _ImageStatistics, maps: tuple[np.ndarray, np.ndarray], params: ChainParams) -> dict[str, np.ndarray]:
    points_ecef = cube.ecef_T_ego.transform_points(cube.points_ego)
    n = len(cube)
    best = {name: np.full(n, np.nan) for name in ("peak", "same_range", "same_range_local", *_ImageStatistics._local_names())}
    for sensor, frame in nearest_frames(statistics.sar, cube.timestamp_ns, params.sar.max_frame_gap_ns).items():
        read = statistics.read(sensor, frame, points_ecef)
        brighter = np.isfinite(read["peak"]) & ~(read["peak"] <= best["peak"])  # NaN best: any reading is brighter
        best = {name: np.where(brighter, read[name], value) for name, value in best.items()}
    power, noise = maps
    power_db = 10.0 * np.log10(power[cube.range_bin, cube.doppler_bin])
    snr_db = power_db - 10.0 * np.log10(noise[cube.range_bin, cube.doppler_bin])
    reading = best["peak"]
    # Points in the radar's shadow (the chain's value is NaN though the image covers them and the SNR
    # is finite) are judged by no candidate, as the chain judges none.
    reading = np.where(np.isnan(cube.sar_db) & np.isfinite(reading) & np.isfinite(snr_db), np.nan, reading)
    return {
        "reading": reading, "local_1m": reading - best["local_1m"], "local_2m": reading - best["local_2m"],
        "local_4m": reading - best["local_4m"], "same_range": reading - best["same_range"],
        "same_range_local": reading - best["same_range_local"], "minus_power": reading - power_db, "minus_snr": reading - snr_db,
        "local_4m_minus_power": reading - best["local_4m"] - power_db, "local_4m_minus_snr": reading - best["local_4m"] - snr_db,
        "same_range_minus_snr": reading - best["same_range"] - snr_db,
    }


def auc_table(values: dict[str, np.ndarray]) -> dict[str, dict[str, float | None]]:
    """Candidate -> band (and ``all``) -> ROC AUC of a low value for on-car points; None without both kinds."""
    table = {}
    for name in CANDIDATES:
        row = {}
        for band in (*RANGE_BANDS, ALL_BAND):
            low, high = BANDS_M[band]
            keep = (values["range_m"] >= low) & (values["range_m"] < high) & np.isfinite(values[name]) & values["ahead"]
            truth = values["on_car"][keep]
            row[band] = float(roc_auc_score(truth, -values[name][keep])) if 0 < truth.sum() < truth.size else None
        table[name] = row
    return table


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("root", help="dataset root")
    parser.add_argument("--splits", default="train,val", help="comma-separated splits (default: train,val)")
    parser.add_argument("--search-radius-m", type=float, default=SAR_SEARCH_RADIUS_M, metavar="M",
                        help="a point's SAR reading: the brightest pixel within M metres of its projection "
                             f"(default: {SAR_SEARCH_RADIUS_M:g}, the chain's)")
    args = parser.parse_args(argv)

    def tables() -> None:
        params = ChainParams(sar=SarTestParams(search_radius_m=args.search_radius_m))
        for split in args.splits.split(","):
            table = auc_table(candidate_values(args.root, split, params))
            print(f"\nsplit {split}\n\n| candidate | " + " | ".join((*RANGE_BANDS, ALL_BAND)) + " |")
            print("|---|" + "---:|" * (len(RANGE_BANDS) + 1))
            for name, row in table.items():
                print(f"| {name} | " + " | ".join("-" if v is None else f"{v:.3f}" for v in row.values()) + " |")

    return run_cli(tables)


if __name__ == "__main__":
    sys.exit(main())
