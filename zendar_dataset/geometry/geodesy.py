"""Geodetic (WGS-84, EPSG:4979) <-> ECEF (EPSG:4978) <-> local ENU, all through pyproj.

Transformers are expensive to build and cheap to call, so they are cached per
process (and per origin for ENU); pyproj gives every thread its own context.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numpy.typing import ArrayLike
from pyproj import Transformer
from pyproj.enums import TransformDirection

from zendar_dataset.geometry.se3 import SE3


@functools.lru_cache(maxsize=1)
def _geodetic_to_ecef_transformer() -> Transformer:
    # always_xy: (lon, lat) order regardless of the CRS's declared axis order.
    return Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)


@functools.lru_cache(maxsize=64)
def _topocentric_transformer(lat_deg: float, lon_deg: float, height_m: float) -> Transformer:
    # +proj=topocentric takes geocentric (ECEF) input and gives east, north, up
    # about the given geodetic origin on the WGS-84 ellipsoid.
    pipeline = (
        "+proj=pipeline +step +proj=topocentric +ellps=WGS84 "
        f"+lat_0={lat_deg!r} +lon_0={lon_deg!r} +h_0={height_m!r}"
    )
    return Transformer.from_pipeline(pipeline)


def _as_points(points: ArrayLike, name: str) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64)
    if p.shape[-1:] != (3,):
        raise ValueError(f"{name} must have shape [..., 3], got {p.shape}")
    return p


def geodetic_to_ecef(lat_deg: ArrayLike, lon_deg: ArrayLike, height_m: ArrayLike) -> np.ndarray:
    """WGS-84 latitude, longitude (degrees) and ellipsoidal height (m) to ECEF.

    Returns
    -------
    np.ndarray
        ``[..., 3]`` float64 ECEF metres; the leading shape is the broadcast of the inputs.
    """
    lat, lon, h = np.broadcast_arrays(
        np.asarray(lat_deg, dtype=np.float64),
        np.asarray(lon_deg, dtype=np.float64),
        np.asarray(height_m, dtype=np.float64),
    )
    x, y, z = _geodetic_to_ecef_transformer().transform(lon, lat, h)
    return np.stack(np.broadcast_arrays(x, y, z), axis=-1).astype(np.float64)


def ecef_to_geodetic(position_ecef: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ECEF ``[..., 3]`` metres to WGS-84 ``(lat_deg, lon_deg, height_m)``, each ``[...]``."""
    p = _as_points(position_ecef, "position_ecef")
    lon, lat, h = _geodetic_to_ecef_transformer().transform(
        p[..., 0], p[..., 1], p[..., 2], direction=TransformDirection.INVERSE
    )
    return np.asarray(lat, np.float64), np.asarray(lon, np.float64), np.asarray(h, np.float64)


def local_up_ecef(position_ecef: ArrayLike) -> np.ndarray:
    """The WGS-84 ellipsoid's outward normal (the local vertical, "up") at ECEF positions.

    Parameters
    ----------
    position_ecef
        ``[..., 3]`` metres.

    Returns
    -------
    np.ndarray
        ``[..., 3]`` float64 unit vectors, ECEF axes.
    """
    lat_deg, lon_deg, _ = ecef_to_geodetic(position_ecef)
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    return np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], axis=-1)


class LocalENU:
    """A local east-north-up frame tangent to the WGS-84 ellipsoid at a geodetic origin.

    Parameters
    ----------
    lat_deg, lon_deg, height_m
        The origin (WGS-84 degrees, ellipsoidal metres); ENU (0, 0, 0) is this point.
    """

    def __init__(self, lat_deg: float, lon_deg: float, height_m: float) -> None:
        self.lat_deg = float(lat_deg)
        self.lon_deg = float(lon_deg)
        self.height_m = float(height_m)
        if not (-90.0 <= self.lat_deg <= 90.0) or not (-180.0 <= self.lon_deg <= 360.0):
            raise ValueError(
                f"ENU origin out of range: lat_deg={self.lat_deg}, lon_deg={self.lon_deg}"
            )
        self.origin_ecef = geodetic_to_ecef(self.lat_deg, self.lon_deg, self.height_m)
        lat = math.radians(self.lat_deg)
        lon = math.radians(self.lon_deg)
        east = [-math.sin(lon), math.cos(lon), 0.0]
        north = [-math.sin(lat) * math.cos(lon), -math.sin(lat) * math.sin(lon), math.cos(lat)]
        up = [math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)]
        self.ecef_R_enu = np.array([east, north, up], dtype=np.float64).T
        self.ecef_R_enu.setflags(write=False)

    def __repr__(self) -> str:
        return (
            f"LocalENU(lat_deg={self.lat_deg!r}, lon_deg={self.lon_deg!r}, "
            f"height_m={self.height_m!r})"
        )

    def __reduce__(self):
        # Rebuild (and re-cache the transformer) in the receiving process.
        return (LocalENU, (self.lat_deg, self.lon_deg, self.height_m))

    @property
    def _transformer(self) -> Transformer:
        return _topocentric_transformer(self.lat_deg, self.lon_deg, self.height_m)

    def ecef_to_enu(self, points_ecef: ArrayLike) -> np.ndarray:
        """ECEF points ``[..., 3]`` (m) to ENU points ``[..., 3]`` (m)."""
        p = _as_points(points_ecef, "points_ecef")
        e, n, u = self._transformer.transform(p[..., 0], p[..., 1], p[..., 2])
        return np.stack(np.broadcast_arrays(e, n, u), axis=-1).astype(np.float64)

    def enu_to_ecef(self, points_enu: ArrayLike) -> np.ndarray:
        """ENU points ``[..., 3]`` (m) to ECEF points ``[..., 3]`` (m)."""
        p = _as_points(points_enu, "points_enu")
        x, y, z = self._transformer.transform(
            p[..., 0], p[..., 1], p[..., 2], direction=TransformDirection.INVERSE
        )
        return np.stack(np.broadcast_arrays(x, y, z), axis=-1).astype(np.float64)

    @property
    def enu_T_ecef(self) -> SE3:
        """The same map as :meth:`ecef_to_enu` as a rigid transform (for composing poses)."""
        rotation = self.ecef_R_enu.T
        return SE3(rotation, -rotation @ self.origin_ecef)

    @property
    def ecef_T_enu(self) -> SE3:
        return SE3(self.ecef_R_enu, self.origin_ecef)
