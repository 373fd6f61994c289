"""The SAR images of one scene as stored by the format, and where ECEF points fall in them.

A stored SAR frame is a complex (or magnitude) image ``sar/<sensor>/image`` ``[N, H, W]`` on a plane
grid given per frame by ``origin_ecef`` (the centre of pixel ``(0, 0)``) and the steps ``di_ecef``,
``dj_ecef`` (metres per pixel along rows and columns), all ECEF (docs/format.md). A magnitude-only
stream (``magnitude_only``) stores real uint32/float32 magnitudes, exact: everything here that uses
magnitudes reads them alike; :meth:`SarFrames.complex_image`, which needs phase, refuses them.
"""

from __future__ import annotations

import functools
from collections import OrderedDict

import numpy as np

from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.format.reader import SceneReader
from zendar_dataset.sar.shadow import RadarShadow

# The SAR value of a point is the brightest pixel within this distance of its projection: one pixel
# around it at the demo profile's 0.16 m pixels. A wider window absorbs more DOA error but lets a weak
# point on a near car read its static neighbours' light. Measured on the default bench's training
# split (36 demo-short scenes, docs/baselines.md "The SAR reading's window"): CFAR points' ROC AUC
# near / mid / far 0.856 / 0.850 / 0.843 with 0.5 m, 0.855 / 0.857 / 0.861 with 0.2 m, 0.760 / 0.852 /
# 0.855 with the nearest pixel alone; the CFAR chain's AP on the validation scenes 68.4 -> 71.9.
SAR_SEARCH_RADIUS_M = 0.2
# Two radars' cubes straddle a SAR frame: one is read against the frame before, the other against
# the frame after, so two frames per sensor are in use at a time.
CACHED_FRAMES_PER_SENSOR = 2


class SarFrames:
    """The SAR images of one scene and where ECEF points fall in them.

    Images are read lazily; the magnitudes of the frames visited last are kept
    (:data:`CACHED_FRAMES_PER_SENSOR` per sensor, least recently used out), as frames are visited
    in time order.

    Parameters
    ----------
    reader : SceneReader
        The scene; every sensor of kind ``sar`` is used (none is fine: ``sensors`` is then empty).
    keep_frames : int or None
        Magnitudes kept per sensor (default :data:`CACHED_FRAMES_PER_SENSOR`); ``None`` keeps every
        frame read, for a caller that visits a scene many times and has the memory.

    Attributes
    ----------
    sensors : list of str
        SAR sensor names.
    timestamps : dict of str to numpy.ndarray
        ``[N]`` int64 ns per sensor.
    origin, di, dj : dict of str to numpy.ndarray
        ``[N, 3]`` float64 ECEF metres per sensor: pixel ``(0, 0)``'s centre and the row and
        column steps.
    images : dict of str to array-like
        ``[N, H, W]`` stored images per sensor (read on access): complex64, or the real magnitudes of a
        magnitude-only sensor.
    shadow : RadarShadow or None
        Where the radars cannot see, from the scene's lidar (:mod:`zendar_dataset.sar.shadow`; read
        at first use); None for a scene without lidar.
    """

    def __init__(self, reader: SceneReader, keep_frames: int | None = CACHED_FRAMES_PER_SENSOR) -> None:
        self.sensors = reader.sensors("sar")
        self.timestamps = {s: reader.timestamps(f"sar/{s}") for s in self.sensors}
        self.origin = {s: reader.array(f"sar/{s}/origin_ecef")[...] for s in self.sensors}
        self.di = {s: reader.array(f"sar/{s}/di_ecef")[...] for s in self.sensors}
        self.dj = {s: reader.array(f"sar/{s}/dj_ecef")[...] for s in self.sensors}
        self.images = {s: reader.array(f"sar/{s}/image") for s in self.sensors}
        self._reader = reader
        self._cache: OrderedDict[tuple[str, int], tuple[np.ndarray, float]] = OrderedDict()
        if keep_frames is not None and not (isinstance(keep_frames, int) and keep_frames >= 1):
            raise ValueError(f"SarFrames: keep_frames must be None or a positive integer, got {keep_frames!r}")
        self._keep = None if keep_frames is None else keep_frames * max(1, len(self.sensors))

    @functools.cached_property
    def shadow(self) -> RadarShadow | None:
        return RadarShadow.of(self._reader)

    def magnitude(self, sensor: str, frame: int) -> tuple[np.ndarray, float]:
        """One image's magnitude and its median non-zero magnitude.

        Parameters
        ----------
        sensor : str
            SAR sensor name.
        frame : int
            Index into the sensor's frames.

        Returns
        -------
        magnitude : numpy.ndarray
            ``[H, W]`` ``|pixel|`` (float32 for a complex64 image; the stored uint32 or float32
            magnitudes, exact, of a magnitude-only one).
        floor : float
            The median of the non-zero magnitudes (1.0 for an all-zero image), the dB reference.
        """
        key = (sensor, frame)
        if key in self._cache:
            self._cache.move_to_end(key)
        else:
            magnitude = np.abs(self.images[sensor][frame])
            floor = float(np.median(magnitude[magnitude > 0])) if np.any(magnitude > 0) else 1.0
            self._cache[key] = (magnitude, floor)
            if self._keep is not None and len(self._cache) > self._keep:
                self._cache.popitem(last=False)
        return self._cache[key]

    def complex_image(self, sensor: str, frame: int) -> np.ndarray:
        """One image ``[H, W]`` complex64, phase included.

        Raises
        ------
        ZendarFormatError
            For a magnitude-only sensor (either layout): its recording holds no phase.
        """
        if self._reader.sar_magnitude_only(sensor):
            raise ZendarFormatError(
                f"{self._reader.scene_id}: sar/{sensor}/image: expected complex pixels (phase), found magnitudes "
                "only (attribute magnitude_only: the recording holds no phase); use magnitude() or image_db()"
            )
        return np.asarray(self.images[sensor][frame], dtype=np.complex64)

    def image_db(self, sensor: str, frame: int) -> tuple[np.ndarray, float]:
        """One image in dB over its median non-zero magnitude.

        Parameters
        ----------
        sensor : str
            SAR sensor name.
        frame : int
            Index into the sensor's frames.

        Returns
        -------
        image_db : numpy.ndarray
            ``[H, W]`` ``20·log10(|pixel| / floor)``; pixels of magnitude 0 give about -600 dB.
        floor : float
            The median of the non-zero magnitudes (:meth:`magnitude`), in the image's units.
        """
        magnitude, floor = self.magnitude(sensor, frame)
        return _to_db(magnitude, floor), floor

    def pixels(self, sensor: str, frame: int, points_ecef: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where ECEF points project onto one image's plane.

        Parameters
        ----------
        sensor : str
            SAR sensor name.
        frame : int
            Index into the sensor's frames.
        points_ecef : numpy.ndarray
            ``[P, 3]`` float64 ECEF metres.

        Returns
        -------
        ij : numpy.ndarray
            ``[P, 2]`` float64 fractional ``(row, column)`` (least-squares projection onto the plane).
        inside : numpy.ndarray
            ``[P]`` bool: the nearest pixel exists.
        """
        basis = np.stack([self.di[sensor][frame], self.dj[sensor][frame]], axis=1)  # [3, 2]
        ij, *_ = np.linalg.lstsq(basis, (points_ecef - self.origin[sensor][frame]).T, rcond=None)
        ij = ij.T
        height, width = self.images[sensor].shape[1:3]
        inside = (ij[:, 0] >= -0.5) & (ij[:, 0] < height - 0.5) & (ij[:, 1] >= -0.5) & (ij[:, 1] < width - 0.5)
        return ij, inside

    def frame_index(self, sensor: str, timestamp_ns: int) -> int | None:
        """Index of the sensor's frame stamped exactly ``timestamp_ns``, or None."""
        found = np.flatnonzero(self.timestamps[sensor] == timestamp_ns)
        return int(found[0]) if found.size else None

    def brightest_db(self, sensor: str, frame: int, points_ecef: np.ndarray,
                     radius_m: float = SAR_SEARCH_RADIUS_M) -> np.ndarray:
        """The brightest pixel near each point, in dB over the image's median magnitude.

        Parameters
        ----------
        sensor : str
            SAR sensor name.
        frame : int
            Index into the sensor's frames.
        points_ecef : numpy.ndarray
            ``[P, 3]`` float64 ECEF metres.
        radius_m : float
            Half the side of the square window searched around each point's nearest pixel, metres
            (rounded to whole pixels; 0 reads the nearest pixel alone).

        Returns
        -------
        numpy.ndarray
            ``[P]`` float64 dB (:meth:`image_db`), the maximum over the pixels within ``radius_m``
            (a square window, clipped at the image's border) of the nearest pixel; NaN for a point
            outside the image.
        """
        ij, inside = self.pixels(sensor, frame, points_ecef)
        out = np.full(points_ecef.shape[0], np.nan)
        if not np.any(inside):
            return out
        magnitude, floor = self.magnitude(sensor, frame)
        step = max(float(np.linalg.norm(self.di[sensor][frame])), 1e-6)
        k = max(0, int(round(radius_m / step)))
        height, width = magnitude.shape
        centre = np.rint(ij[inside]).astype(np.int64)
        offsets = np.arange(-k, k + 1)
        # Every window at once, [P, 2k+1, 2k+1]; clipping repeats border pixels, which leaves the
        # maximum that of the clipped window. The maximum is taken on magnitudes and then turned
        # into dB: the conversion is monotonic, so this equals the maximum of the dB image.
        rows = np.clip(centre[:, 0, None, None] + offsets[None, :, None], 0, height - 1)
        cols = np.clip(centre[:, 1, None, None] + offsets[None, None, :], 0, width - 1)
        peak = magnitude[rows, cols].reshape(centre.shape[0], -1).max(axis=1)
        out[inside] = _to_db(peak, floor)
        return out


def _to_db(magnitude: np.ndarray, floor: float) -> np.ndarray:
    """``20·log10(magnitude / floor)`` in the magnitude's precision, floored at 1e-30 (no -inf)."""
    return 20.0 * np.log10(np.maximum(magnitude, 1e-30) / floor)
