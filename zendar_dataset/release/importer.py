"""Converting release folders into format-v1 scenes (``zendar-data import-release``).

Each scene of the release (``release/discover.py``) becomes one scene store
written through :class:`zendar_dataset.format.writer.DatasetWriter`: atomic
(a scene appears only when complete), resumable (complete scenes are kept and
skipped), and the source is only read.  Everything the release does not say
and the importer had to decide (``release/assumptions.py``) is recorded as an
assumption: in the summary (``release/summary.py``), and in the scene's root
attribute ``release_import``.  Every stream is read through one loop
(``release/decoded.py``); the writers here turn its records into format-v1 arrays.
"""

from __future__ import annotations

import itertools
import json
import os
import pathlib
import re
from collections.abc import Callable, Iterator, Mapping

import numpy as np

from zendar_dataset.atomic_files import write_json_atomic
from zendar_dataset.errors import ZendarError, ZendarFormatError
from zendar_dataset.format import stores
from zendar_dataset.format.schema import BACKEND_SUFFIX, DATASET_JSON, SPLITS
from zendar_dataset.format.writer import DatasetWriter, check_scene_id
from zendar_dataset.output_location import other_entries
from zendar_dataset.geometry.geodesy import LocalENU
from zendar_dataset.release import assumptions as assume
from zendar_dataset.release import records as rec
from zendar_dataset.release import sides as side_evidence
from zendar_dataset.release.decoded import OpenedStream, decoded_records, finish_summary, open_stream
from zendar_dataset.release.discover import SceneSource, find_scenes, fingerprint
from zendar_dataset.release.lidar_rows import StoredSweep, stored_sweep
from zendar_dataset.release.pixel_order import vote_pixel_order
from zendar_dataset.release.read_ahead import READ_AHEAD_RECORDS, ReadAhead, read_ahead
from zendar_dataset.release.summary import SUMMARY_JSON, ImportSummary, SceneSummary, StreamSummary
from zendar_dataset.release.tracklog_attitude import attitude_evidence, check_attitude
from zendar_dataset.release.wire import WireError


def _prefix(path: pathlib.Path, suffix: str) -> str | None:
    name = path.name.split(".")[0]
    return name[: -len(suffix)] if name.endswith(suffix) and len(name) > len(suffix) else None


def _sar_frames(opened: OpenedStream, probe: bool = False) -> Iterator[rec.SarFrame]:
    """The SAR frames of an ``Image`` stream (:func:`decoded_records`; records without an image are counted)."""
    yield from decoded_records(opened, rec.sar_frame_record, probe=probe)


def _sar_grids(opened: OpenedStream, i_fastest: bool) -> Iterator[tuple[rec.SarFrame, tuple[np.ndarray, str] | ValueError]]:
    """Each SAR frame with its image in C order and what it holds (:func:`records.sar_grid`), or the
    ValueError that says why it has none. The copy into C order (a transpose when ``i_fastest``) is made
    here so that, under :func:`read_ahead`, it runs on the decoding thread (numpy copies release the GIL)."""
    for frame in _sar_frames(opened):
        try:
            image, holds = rec.sar_grid(frame, i_fastest)
        except ValueError as exc:
            yield frame, exc
            continue
        yield frame, (np.ascontiguousarray(image), holds)


#: Bytes of lidar records decoded ahead at most (their points waiting, converted, take about as much): the
#: lidar, most of a scene's bytes, is decoded on the second core while the images and cubes are written.
LIDAR_READ_AHEAD_BYTES = 128 << 20


def _lidar_sweeps(lidars: dict[str, OpenedStream], enu: LocalENU) -> Iterator[tuple[str, StoredSweep | None, bool]]:
    """Every lidar's sweeps as stored, ``(name, sweep, points computed from ECEF)``, lidar after lidar, each
    ended by ``(name, None, False)``. Points are taken in ENU from ECEF where the release gives no
    sensor-frame position, or gives ECEF under that name."""
    for name, opened in lidars.items():
        for sweep in decoded_records(opened, rec.lidar_sweep):
            local = sweep.position_local
            from_ecef = local is None or rec.looks_ecef(local)
            if from_ecef:
                local = enu.ecef_to_enu(sweep.position_ecef) if sweep.position_ecef.size else np.zeros((0, 3))
            yield name, stored_sweep(sweep.timestamp_s, local, sweep.position_ecef, sweep.intensity), from_ecef
        yield name, None, False


def _lidar_read_ahead(lidars: dict[str, OpenedStream], enu: LocalENU) -> ReadAhead:
    """:func:`_lidar_sweeps` decoding from now on, up to :data:`LIDAR_READ_AHEAD_BYTES` of records ahead."""
    largest = max((int(o.stream.spans()[2].max(initial=0)) for o in lidars.values()), default=0)
    return ReadAhead(_lidar_sweeps(lidars, enu), max(READ_AHEAD_RECORDS, LIDAR_READ_AHEAD_BYTES // max(largest, 1)))


class _Stamps:
    """Strictly increasing int64 ns per output stream; records out of order are skipped with a reason."""

    def __init__(self, summary: StreamSummary) -> None:
        self.last: int | None = None
        self.summary = summary
        self.dropped: dict[str, int] = {}

    def take(self, seconds: float) -> int | None:
        if not np.isfinite(seconds) or seconds < 0:
            return self._drop("non-finite or negative timestamp")
        ns = rec.gps_seconds_to_ns(seconds)
        if self.last is not None and ns <= self.last:
            return self._drop("timestamp not after the previous record's")
        self.last = ns
        return ns

    def _drop(self, why: str) -> None:
        self.dropped[why] = self.dropped.get(why, 0) + 1

    def report(self) -> None:
        self.summary.skipped.extend(f"{n} records: {why}" for why, n in self.dropped.items())


def _tracklog(opened: list[OpenedStream], scene: SceneSummary):
    if not opened:
        return None
    first, *rest = opened
    for other in rest:
        other.summary.skipped.append(f"a second tracklog; {first.summary.path} is the scene's tracklog")
    _, offsets, lengths = first.stream.spans()
    try:
        # Column-wise: a tracklog has hundreds of thousands of records of one layout.
        unknown: dict[str, int] = {}
        seconds, position, attitude = rec.poses(first.stream.buffer, offsets, lengths, unknown)
        first.summary.records += offsets.shape[0]
        for name, count in unknown.items():
            first.stream.unknown_fields[name] = first.stream.unknown_fields.get(name, 0) + count
    except WireError:
        # Some record does not decode: go record by record, so each is reported (or skipped) where it is.
        decoded = [rec.pose(record) for record in decoded_records(first)]
        seconds = np.array([d.timestamp_s for d in decoded])
        position = np.array([d.position_ecef for d in decoded]).reshape(-1, 3)
        attitude = np.array([d.attitude_wxyz for d in decoded]).reshape(-1, 4)
    norms = np.linalg.norm(attitude, axis=1)
    usable = np.all(np.isfinite(position), axis=1) & np.isfinite(norms) & (norms > 0)
    bad = int(np.count_nonzero(~usable))
    stamps = _Stamps(first.summary)
    t, keep = [], []
    for k in np.flatnonzero(usable).tolist():
        ns = stamps.take(float(seconds[k]))
        if ns is not None:
            t.append(ns)
            keep.append(k)
    stamps.report()
    p, q = position[keep], attitude[keep] / norms[keep, None]
    if bad:
        first.summary.skipped.append(f"{bad} records with NaN position or attitude")
    if not t:
        first.summary.skipped.append("no usable pose")
        return None
    first.summary.written_to = "tracklog"
    scene.assumptions.append(assume.TRACKLOG_ATTITUDE)
    return np.asarray(t, np.int64), p, q


class _SceneImport:
    """Everything about importing one scene; :meth:`run` writes it."""

    def __init__(self, source: SceneSource, src: pathlib.Path, skip_corrupt: bool, problems: list[str], digest: str) -> None:
        self.source = source
        self.summary = SceneSummary(source.scene_id, str(source.folder), fingerprint=digest)
        self.opened = [open_stream(path, src, skip_corrupt, problems) for path in source.files]
        self.summary.streams = [o.summary for o in self.opened]
        self.sides: dict[str, str] = {}
        # Each lidar's (time, ECEF points) decoded so far for the pixel-order checks, shared by every radar.
        self._lidar_probes: dict[pathlib.Path, tuple[list[tuple[float, np.ndarray]], Iterator[tuple[float, np.ndarray]]]] = {}

    def radar_serials(self) -> set[str]:
        """The serials its SAR and detection files name."""
        return set(self._keyed(self._by_kind("Image"), "_images", report=False)) | set(
            self._keyed(self._by_kind("TrackerState"), "_points", report=False)
        )

    def decide_sides(self, stated: Mapping[str, str]) -> None:
        """Serial -> side (``release/sides.py``), and the tracklog's attitude convention checked against
        the path (``release/tracklog_attitude.py``), for every scene before any is written.

        Raises :class:`ZendarFormatError` when the image attitude and the path driven disagree, or
        the tracklog's attitude is not the convention the import takes.
        """
        images = self._keyed(self._by_kind("Image"), "_images", report=False)
        points = self._keyed(self._by_kind("TrackerState"), "_points", report=False)
        tracklogs = self._by_kind("Position")
        path = None
        if tracklogs:
            seconds, position, attitude = side_evidence.tracklog_poses(tracklogs[0])
            path = side_evidence.tracklog_path(seconds, position)
            self._check_tracklog_attitude(seconds, position, attitude)
        if path is None:
            path = side_evidence.frames_path(itertools.chain.from_iterable(_sar_frames(o, probe=True) for o in images.values()))
        evidence = side_evidence.gather_evidence(images, points, path, lambda opened: _sar_frames(opened, probe=True))
        self.sides = side_evidence.decide_sides(self.source.scene_id, evidence, stated, self.summary.assumptions)

    def _check_tracklog_attitude(self, seconds: np.ndarray, position: np.ndarray, attitude: np.ndarray) -> None:
        usable = np.isfinite(seconds) & np.all(np.isfinite(position), axis=1) & np.all(np.isfinite(attitude), axis=1)
        usable &= np.linalg.norm(np.where(np.isfinite(attitude), attitude, 0.0), axis=1) > 0
        times_s, first = np.unique(seconds[usable], return_index=True)
        evidence = attitude_evidence(times_s, position[usable][first], attitude[usable][first])
        self.summary.assumptions.append(check_attitude(self.source.scene_id, *evidence))

    def _by_kind(self, name: str) -> list[OpenedStream]:
        return [o for o in self.opened if o.stream is not None and o.stream.kind.name == name and o.stream.kind.converted]

    def run(self, writer: DatasetWriter) -> None:
        scene = self.summary
        tracklog = _tracklog(self._by_kind("Position"), scene)
        images = self._keyed(self._by_kind("Image"), "_images")
        points = self._keyed(self._by_kind("TrackerState"), "_points")
        rd_frames = self._keyed(self._by_kind("RangeDopplerFrame"), "_rd")

        def rename(serial: str) -> str:
            return self.sides.get(serial, serial)

        models = self._models(list(rd_frames))
        assumed_models = set()
        for name, opened in rd_frames.items():
            first = next(decoded_records(opened, probe=True), None)
            if name not in models and first is not None and len(first["data"]) == 8 * int(np.prod(assume.PAPER_CUBE_SHAPE)):
                models[name] = assume.paper_model()
                assumed_models.add(name)
        radars = sorted({rename(s) for s in images} | {rename(s) for s in points} | set(rd_frames))
        calibration = {"imu": assume.imu_entry(scene.assumptions)}
        for radar in radars:
            calibration[radar] = assume.radar_entry(radar, models.get(radar), scene.assumptions, radar in assumed_models)
        lidars = self._keyed(self._by_kind("LidarPointsFrame"), "")
        cameras = self._keyed(self._by_kind("CameraIndexRecord"), "", camera=True)
        for name in list(lidars) + list(cameras):
            calibration[name] = assume.sensor_entry(name, scene.assumptions)
        enu_origin = assume.enu_origin(
            None if tracklog is None else tracklog[1][0],
            itertools.chain.from_iterable(_sar_frames(opened, probe=True) for opened in images.values()),
            scene.assumptions,
        )
        enu = LocalENU(**enu_origin)
        # The lidar (most of a scene's bytes) is decoded from now on, beside the writing of the other streams.
        with _lidar_read_ahead(lidars, enu) as lidar_sweeps, writer.scene(
            self.source.scene_id, enu_origin=enu_origin, calibration={"sensors": calibration}
        ) as out:
            if tracklog is not None:
                out.write_tracklog(*tracklog)
            for serial, opened in images.items():
                i_fastest = self._pixel_order(rename(serial), opened, points.get(serial), list(lidars.values()))
                self._write_sar(out, rename(serial), serial, opened, i_fastest)
            for name, opened in rd_frames.items():
                self._write_cubes(out, name, opened, models.get(name))
            for serial, opened in points.items():
                self._write_detections(out, rename(serial), opened)
            for name, opened in lidars.items():
                self._write_lidar(out, name, opened, lidar_sweeps)
            for name, opened in cameras.items():
                self._write_camera_index(out, name, opened)
            for opened in self.opened:
                finish_summary(opened)
            out.write_attrs(
                "",
                {
                    "release_import": {
                        "source": str(self.source.folder),
                        "fingerprint": scene.fingerprint,
                        "assumptions": scene.assumptions,
                    }
                },
            )

    def _keyed(self, opened: list[OpenedStream], suffix: str, camera: bool = False, report: bool = True) -> dict[str, OpenedStream]:
        """Streams keyed by sensor name: the file-name prefix before ``suffix``, else the parent folder's name
        (a second stream for a name is skipped, and said so in its summary when ``report``).

        Cameras are named after their folders (``camera/left/index.pbs`` -> ``camera_left``), always starting
        with ``camera`` so that no camera takes a radar's name in the scene's shared sensor names.
        """
        out: dict[str, OpenedStream] = {}
        for item in opened:
            name = _prefix(item.path, suffix) if suffix else None
            if camera:
                folders = "_".join(item.path.relative_to(self.source.folder).parts[:-1])
                name = folders or item.path.name.split(".")[0]
                name = name if name.lower().startswith("camera") else f"camera_{name}"
            elif name is None:
                stem = item.path.name.split(".")[0]
                # Raw-acquisition layout: <sensor>/<NN>/stream.pbs is named by its folders.
                folders = "_".join(item.path.relative_to(self.source.folder).parts[:-1])
                name = folders if stem == "stream" and folders else stem
            name = re.sub(r"[^A-Za-z0-9_-]+", "_", name)
            if name in out:
                if report:
                    item.summary.skipped.append(f"a second stream for sensor {name!r}; {out[name].summary.path} was used")
                continue
            out[name] = item
        return out

    def _models(self, rd_names: list[str]) -> dict[str, rec.RangeDopplerModel]:
        models = []
        for item in self.opened:
            if item.model is not None:
                models.append((item, item.model))
            elif item.stream is not None and item.stream.kind.name == "RangeDopplerImageModel":
                record = next(decoded_records(item), None)
                if record is not None:
                    models.append((item, rec.rd_model(record)))
                if len(item.stream) > 1:
                    item.summary.skipped.append(f"{len(item.stream) - 1} further model records ignored (the first is used)")
        out = {}
        for name in rd_names:
            named = [(i, m) for i, m in models if name.lower() in i.path.name.lower()]
            if len(named) == 1:
                out[name] = named[0][1]
                named[0][0].summary.written_to = f"calibration/{name}"
            elif len(models) == 1:
                out[name] = models[0][1]
                models[0][0].summary.written_to = "calibration"
                self.summary.assumptions.append(assume.shared_model(models[0][0].summary.path, name))
        return out

    def _pixel_order(self, name: str, opened: OpenedStream, points: OpenedStream | None, lidars: list[OpenedStream]) -> bool:
        """Check the pixel order against this radar's detections, then the lidar if still undecided (``pixel_order.py``)."""
        frames = []
        for frame in _sar_frames(opened, probe=True):
            frames.append(frame)
            if len(frames) >= 20:
                break
        if not frames:
            return True
        last_s = max(f.timestamp_s for f in frames) + 1.0
        probes: list[tuple[float, np.ndarray]] = []
        i_fastest, evidence = None, "no detections or lidar points to check against"
        for source in ([points] if points else []) + lidars:
            if source.stream.kind.name == "TrackerState":
                known = ((d.timestamp_s, d.columns["position_ecef"]) for d in decoded_records(source, rec.detections, probe=True))
            else:
                known = self._lidar_probe(source, last_s)
            for probe in known:
                if probe[0] > last_s:
                    break
                probes.append(probe)
            i_fastest, evidence = vote_pixel_order(frames, probes)
            if i_fastest is not None:
                break
        return assume.pixel_order(name, i_fastest, evidence, self.summary.assumptions)

    def _lidar_probe(self, lidar: OpenedStream, last_s: float) -> list[tuple[float, np.ndarray]]:
        """The lidar's (time, ECEF points) in file order up to the first sweep after ``last_s``, decoded once
        for all radars (the sweeps are the bulk of a scene's bytes)."""
        if lidar.path not in self._lidar_probes:
            # Copies: a view would keep each whole decoded sweep alive while the probes are kept.
            sweeps = (
                (s.timestamp_s, np.ascontiguousarray(s.position_ecef))
                for s in decoded_records(lidar, rec.lidar_sweep, probe=True)
            )
            self._lidar_probes[lidar.path] = ([], sweeps)
        seen, rest = self._lidar_probes[lidar.path]
        while not seen or seen[-1][0] <= last_s:
            sweep = next(rest, None)
            if sweep is None:
                break
            seen.append(sweep)
        return seen

    def _write_sar(self, out, name: str, serial: str, opened: OpenedStream, i_fastest: bool) -> None:
        stamps = _Stamps(opened.summary)
        layout = None  # (holds, dtype) of the stream's first frame: format v1 keeps one image dtype per stream
        bad: dict[str, int] = {}
        shape = None
        for frame, grid in read_ahead(_sar_grids(opened, i_fastest)):
            if isinstance(grid, ValueError):
                bad[str(grid)] = bad.get(str(grid), 0) + 1
                continue
            image, holds = grid
            if not all(np.all(np.isfinite(v)) for v in (frame.origin_ecef, frame.di_ecef, frame.dj_ecef)):
                bad["NaN in the image model"] = bad.get("NaN in the image model", 0) + 1
                continue
            if shape is not None and image.shape != shape:
                # Format v1 keeps one image shape per stream.
                why = f"shape {list(image.shape)} differs from the stream's first {list(shape)}"
                bad[why] = bad.get(why, 0) + 1
                continue
            if layout is not None and (holds, image.dtype) != layout:
                why = f"{holds} pixels ({image.dtype.name}) differ from the stream's first frame's {layout[0]} ({layout[1].name})"
                bad[why] = bad.get(why, 0) + 1
                continue
            ns = stamps.take(frame.timestamp_s)
            if ns is None:
                continue
            shape, layout = image.shape, (holds, image.dtype)
            out.append_sar(
                name, ns, image, frame.origin_ecef, frame.di_ecef, frame.dj_ecef, [ns, ns], magnitude_only=holds == "magnitude"
            )
        stamps.report()
        opened.summary.skipped.extend(f"{n} frames: {why}" for why, n in bad.items())
        if layout is None:
            return
        opened.summary.written_to = f"sar/{name}"
        magnitude_only = layout[0] == "magnitude"
        out.write_attrs(f"sar/{name}", {"magnitude_only": magnitude_only, "serial": serial, "aperture_known": False})
        self.summary.assumptions += assume.sar_pixels_and_aperture(name, magnitude_only)

    def _write_cubes(self, out, name: str, opened: OpenedStream, model: rec.RangeDopplerModel | None) -> None:
        if model is None:
            opened.summary.skipped.append("no RangeDopplerImageModel found for it: the cube shape is unknown")
            return
        shift, why = assume.doppler_shift(model)
        if shift is None:
            opened.summary.skipped.append(why)
            return
        shape = (model.range_axis[2], model.doppler_axis[2], model.num_rx)
        stamps = _Stamps(opened.summary)
        bad = 0
        for record in read_ahead(decoded_records(opened)):
            data = record["data"]
            if len(data) != 8 * int(np.prod(shape)):
                bad += 1
                continue
            ns = stamps.take(record["timestamp"])
            if ns is None:
                continue
            cube = np.frombuffer(data, "<c8").reshape(shape)
            out.append_radar(name, ns, np.fft.fftshift(cube, axes=1) if shift == "fftshift" else cube)
        stamps.report()
        if bad:
            opened.summary.skipped.append(f"{bad} frames whose size is not 8 x {shape} bytes")
        opened.summary.written_to = f"radar/{name}"
        self.summary.assumptions += assume.cube_axes(name, why)

    def _write_detections(self, out, name: str, opened: OpenedStream) -> None:
        stamps = _Stamps(opened.summary)
        times, offsets, parts = [], [0], []
        for found in read_ahead(decoded_records(opened, rec.detections)):
            ns = stamps.take(found.timestamp_s)
            if ns is None:
                continue
            times.append(ns)
            offsets.append(offsets[-1] + found.columns["range_m"].shape[0])
            parts.append(found.columns)
        stamps.report()
        if not times:
            return
        columns = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
        nan = int(np.count_nonzero(~np.all(np.isfinite(columns["position_ecef"]), axis=1)))
        out.write_detections(name, times, offsets, columns)
        opened.summary.written_to = f"detections/{name}"
        if nan:
            opened.summary.notes.append(f"{nan} detections with NaN ECEF position kept as NaN")
        self.summary.assumptions.append(assume.detection_fields(name, opened.stream.kind.generation))

    def _write_lidar(self, out, name: str, opened: OpenedStream, sweeps: Iterator[tuple[str, StoredSweep | None, bool]]) -> None:
        """Write lidar ``name`` from ``sweeps`` (:func:`_lidar_sweeps`), taking them up to this lidar's end mark."""
        stamps = _Stamps(opened.summary)
        ecef_parts, dropped, points_in_enu = [], 0, False
        for _, sweep, from_ecef in sweeps:  # in ``lidars``' order, as they are written
            if sweep is None:
                break
            points_in_enu |= from_ecef
            dropped += sweep.dropped
            ns = stamps.take(sweep.timestamp_s)
            if ns is None:
                continue
            out.append_lidar(name, ns, sweep.points)
            ecef_parts.append(sweep.position_ecef)
        stamps.report()
        if not ecef_parts:
            return
        out.write_extra_array(f"lidar/{name}/position_ecef", np.concatenate(ecef_parts).reshape(-1, 3))
        opened.summary.written_to = f"lidar/{name}"
        if dropped:
            opened.summary.skipped.append(f"{dropped} points with NaN positions")
        if points_in_enu:
            out.write_attrs(f"lidar/{name}", {"points_frame": "enu"})
        self.summary.assumptions.append(assume.lidar_frame(name, points_in_enu))

    def _write_camera_index(self, out, name: str, opened: OpenedStream) -> None:
        stamps = _Stamps(opened.summary)
        times, index = [], []
        for record in decoded_records(opened):
            ns = stamps.take(record["timestamp"]["common"])
            if ns is not None:
                times.append(ns)
                index.append(record["frame_index"])
        stamps.report()
        if times:
            out.write_camera_index(name, times, index)
            opened.summary.written_to = f"camera_index/{name}"
            self.summary.assumptions.append(assume.camera_video(name))

    def close(self) -> None:
        for opened in self.opened:
            if opened.stream is not None:
                opened.stream.close()


class _EarlierDataset:
    """What an earlier import left in OUT: its ``dataset.json`` (name, splits, scenes and their stores,
    whichever backend) and the scene stores on disk; all kept as they are by a later import."""

    def __init__(self, out: pathlib.Path) -> None:
        self.out = out
        self.name: str | None = None
        self.splits: dict[str, list[str]] = {}
        self.paths: dict[str, str] = {}  # scene id -> store path relative to OUT
        self.listed: set[str] = set()  # the scenes dataset.json lists
        path = out / DATASET_JSON
        if not path.exists():
            return
        try:
            document = json.loads(path.read_text(encoding="utf-8"))
            self.splits = {str(k): [str(s) for s in v] for k, v in document["splits"].items()}
            self.paths = {str(k): str(v["path"]) for k, v in document.get("scenes", {}).items()}
            self.listed = set(self.paths)
            name = document.get("name")
            self.name = name if isinstance(name, str) else None
        except (ValueError, KeyError, TypeError, AttributeError) as exc:
            raise ZendarError(
                f"{path}: expected the dataset.json of an earlier import to resume, found unreadable JSON ({exc})"
            ) from None

    def missing(self) -> list[str]:
        """A problem for every scene ``dataset.json`` lists (or puts in a split) without its store."""
        problems = []
        for scene_id in sorted(set(self.paths) | {s for ids in self.splits.values() for s in ids}):
            if self.store_of(scene_id) is None:
                where = self.paths.get(scene_id, f"scenes/{scene_id}.*")
                problems.append(
                    f"{self.out / DATASET_JSON}: lists scene {scene_id!r}, whose store {self.out / where} is missing; "
                    "restore it, or take the scene out of dataset.json"
                )
        return problems

    def store_of(self, scene_id: str) -> pathlib.Path | None:
        """The scene's store in OUT: where ``dataset.json`` says, else ``scenes/<id>.zarr`` or ``.h5``
        (an earlier import's scene whose run stopped before ``dataset.json``); None when there is none."""
        if scene_id in self.paths:
            path = self.out / self.paths[scene_id]
            return path if path.exists() else None
        for suffix in BACKEND_SUFFIX.values():
            path = self.out / "scenes" / f"{scene_id}{suffix}"
            if path.exists():
                self.paths[scene_id] = path.relative_to(self.out).as_posix()
                return path
        return None


def _check_out(out: pathlib.Path) -> None:
    """OUT is new, an empty folder, or a dataset an import can resume or add to (``dataset.json`` or
    ``scenes/`` in it); its ``release_import.json``, if any, is an earlier import's summary (so that
    merging into it overwrites nothing of the user's)."""
    if out.exists() and not out.is_dir():
        raise ZendarError(f"{out}: OUT is a file; give a new or empty folder, or a dataset to add to")
    if not out.is_dir() or not any(out.iterdir()):
        return
    if not (out / DATASET_JSON).is_file() and not (out / "scenes").is_dir():
        raise ZendarError(
            f"{out}: OUT holds files that are not a dataset ({other_entries(out)}); "
            "give a new or empty folder, or a dataset to add to"
        )
    summary = out / SUMMARY_JSON
    if summary.exists():
        try:
            document = json.loads(summary.read_text(encoding="utf-8"))
            ours = isinstance(document, dict) and isinstance(document.get("scenes"), list) and "source" in document
        except (ValueError, UnicodeDecodeError):
            ours = False
        if not ours:
            raise ZendarError(f"{summary}: expected an earlier import's summary, found another file; move it out of OUT")


def _named_serials(files: list[pathlib.Path]) -> set[str]:
    """Radar serials a scene's file names give (``<serial>_images.pbs``, ``<serial>_points.pbs``)."""
    return {serial for path in files for suffix in ("_images", "_points") if (serial := _prefix(path, suffix))}


def _merged_summary(out: pathlib.Path, summary: ImportSummary) -> dict:
    """``release_import.json``'s new content: this run's summary, where every scene an earlier run
    imported keeps that run's account of it (its streams, skips, unknown fields and assumptions)
    instead of "already imported", and the scenes of earlier runs not in this one are kept."""
    document = summary.to_json()
    path = out / SUMMARY_JSON
    earlier = json.loads(path.read_text(encoding="utf-8")) if path.exists() else {}  # checked by _check_out
    before = {s["scene_id"]: s for s in earlier.get("scenes", []) if isinstance(s, dict) and isinstance(s.get("scene_id"), str)}
    merged = []
    for scene in document["scenes"]:
        prior = before.pop(scene["scene_id"], None)
        merged.append(prior if prior is not None and scene["status"] == "already imported" else scene)
    merged.extend(before.values())
    document["scenes"] = sorted(merged, key=lambda scene: scene["scene_id"])
    return document


def _imported_from(scene_path: pathlib.Path) -> dict:
    """The ``release_import`` attribute of a scene written earlier (empty when it has none)."""
    store = stores.open_store(scene_path)
    try:
        return stores.read_attrs(store.root).get("release_import") or {}
    finally:
        store.close()


def _check_stated_sides(stated: Mapping[str, str], imports: list[_SceneImport], scenes: list[SceneSource],
                        problems: list[str]) -> bool:
    """Every stated side is left or right, given once, to a serial some scene of SRC holds (one already
    imported too, so that the same command run again resumes). Returns whether they can be used: a side
    stated wrongly is the one problem to fix first (the sides decided without it would mislead)."""
    bad = {serial: side for serial, side in stated.items() if side not in side_evidence.SIDES}
    if bad:
        problems.append(f"--sides: sides must be left or right, got {bad}")
    twice = len(set(stated.values())) != len(stated)
    if twice:
        problems.append(f"--sides: one side is given to more than one serial ({stated})")
    known = set().union(*(job.radar_serials() for job in imports), *(_named_serials(s.files) for s in scenes))
    # With every scene imported already there is nothing to state sides for: the command run again resumes.
    unknown = sorted(set(stated) - known) if imports else []
    if unknown:
        problems.append(
            f"--sides: {', '.join(unknown)} is not a radar serial of the scenes to import "
            f"(their serials: {', '.join(sorted(known)) or 'none'})"
        )
    return not (bad or twice or unknown)


_SPLIT_NAME = re.compile(r"^[A-Za-z0-9_-]+$")


def import_release(
    src: str | os.PathLike,
    out: str | os.PathLike,
    *,
    scene_id: str | None = None,
    split: str = "train",
    skip_corrupt: bool = False,
    backend: str = "zarr",
    sides: Mapping[str, str] | None = None,
    log: Callable[[str], None] | None = None,
) -> ImportSummary:
    """Convert every scene of a release folder into a format-v1 dataset at ``out``.

    Parameters
    ----------
    src
        A release folder (one scene or a tree of ``<date>_<time>/<NNN>`` scenes), or one stream file.
        Only read.
    out
        Dataset root to create or resume (scenes already complete there are kept and skipped).
    scene_id
        Id for the scene when ``src`` holds exactly one.
    split
        Split every imported scene goes into.
    skip_corrupt
        Skip truncated and corrupt stretches of streams (reported) instead of stopping.
    backend
        ``"zarr"`` or ``"hdf5"``.
    sides
        Radar serial -> ``"left"`` or ``"right"``, stated by the user (``--sides``): taken instead of
        deciding (``release/sides.py``); in a scene where it names some radars, the others keep their serials.
    log
        Called with each scene id as it starts.

    Raises
    ------
    ZendarError
        A problem with the source (every unreadable stream listed, and every scene whose image attitude
        and path driven disagree on left and right) or the arguments.
    """
    src_path, out_path = pathlib.Path(src), pathlib.Path(out)
    if not src_path.exists():
        raise ZendarError(f"{src_path}: no such release folder or file")
    if not _SPLIT_NAME.fullmatch(split):
        raise ZendarError(f"--split: expected a split name of letters, digits, '_' or '-' (e.g. {', '.join(SPLITS)}), got {split!r}")
    resolved_src, resolved_out = src_path.resolve(), out_path.resolve()
    if resolved_out == resolved_src or (src_path.is_dir() and resolved_src in resolved_out.parents):
        raise ZendarError(f"{out_path}: the output must lie outside the release folder {src_path} (it is never modified)")
    _check_out(out_path)
    scenes = find_scenes(src_path)
    if not scenes:
        raise ZendarError(f"{src_path}: no stream files (*.pbs, *.pbs.gz, *.pb) found")
    if scene_id is not None:
        if len(scenes) != 1:
            names = ", ".join(s.scene_id for s in scenes)
            raise ZendarError(f"--scene-id: {src_path} holds {len(scenes)} scenes ({names}); give it for one scene only")
        scenes[0].scene_id = check_scene_id(scene_id)
    earlier = _EarlierDataset(out_path)
    summary = ImportSummary(str(src_path), str(out_path))
    absolute_src = pathlib.Path(os.path.abspath(src_path))  # as find_scenes names the files
    base = absolute_src if src_path.is_dir() else absolute_src.parent
    imports = []
    problems: list[str] = earlier.missing()
    try:
        for source in scenes:
            digest = fingerprint(source.files)
            existing = earlier.store_of(source.scene_id)
            if existing is not None:
                imported_from = _imported_from(existing)
                recorded = imported_from.get("fingerprint")
                if recorded is not None and recorded != digest:
                    problems.append(
                        f"{existing}: scene {source.scene_id!r} already holds a different recording "
                        f"(imported from {imported_from.get('source')}; {source.folder} differs in content); "
                        "import it into another OUT or give it another --scene-id"
                    )
                    continue
                done = SceneSummary(source.scene_id, str(source.folder), status="already imported", fingerprint=recorded)
                summary.scenes.append(done)
                continue
            imports.append(_SceneImport(source, base, skip_corrupt, problems, digest))
        stated = dict(sides or {})
        if _check_stated_sides(stated, imports, scenes, problems):
            # Decided even when other problems were found, so that all of them are listed at once.
            for job in imports:
                try:
                    job.decide_sides(stated)
                except ZendarFormatError as exc:
                    problems.extend(exc.problems)
        if problems:
            raise ZendarFormatError(f"{src_path}: {len(problems)} problems: " + "; ".join(problems), problems)
        # Only now, with nothing found wrong, is OUT created.
        writer = DatasetWriter(out_path, earlier.name or "zendar-release", backend=backend, overwrite=True)
        for job in imports:
            if log:
                log(job.source.scene_id)
            job.run(writer)
            summary.scenes.append(job.summary)
            job.close()
    finally:
        for job in imports:
            job.close()
    splits = earlier.splits
    for scene in summary.scenes:
        # A scene dataset.json lists already keeps its split, or none if its owner took it out of them.
        if scene.scene_id not in earlier.listed and not any(scene.scene_id in ids for ids in splits.values()):
            splits.setdefault(split, []).append(scene.scene_id)
    for name in SPLITS:
        splits.setdefault(name, [])
    writer.finalize(splits, existing_paths=earlier.paths)
    write_json_atomic(out_path / SUMMARY_JSON, _merged_summary(out_path, summary))
    return summary
