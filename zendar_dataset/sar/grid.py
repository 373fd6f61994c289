"""The SAR image model of format v1: a planar grid of pixels in a Cartesian frame.

Pixel ``image[i, j]`` sits at ``origin + i·di + j·dj``. The frame is whatever the
vectors are expressed in: ECEF metres in the dataset files, a local ENU or ego frame
in computations (:meth:`ImageGrid.transformed` moves a grid between frames).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from zendar_dataset.errors import ZendarFormatError

# di and dj closer to parallel than this (|sin| of the angle between them) leave
# the image plane undefined.
_MIN_SIN_ANGLE = 1e-9


def _vector3(name: str, value: Any, problems: list[str]) -> np.ndarray:
    array = np.asarray(value, dtype=np.float64)
    if array.shape != (3,):
        problems.append(f"{name} must have shape (3,), got {array.shape}")
        return np.zeros(3)
    if not np.all(np.isfinite(array)):
        problems.append(f"{name} must be finite, got {array.tolist()}")
    return array


@dataclass(frozen=True)
class ImageGrid:
    """A planar pixel grid: pixel ``(i, j)`` at ``origin + i·di + j·dj``.

    Parameters
    ----------
    origin : array_like, shape (3,)
        Position of pixel (0, 0) in metres, float64.
    di, dj : array_like, shape (3,)
        Step in metres per +1 in ``i`` (rows) and ``j`` (columns). They need not be
        orthogonal or of equal length, only not parallel.
    shape : tuple of int
        ``(H, W)``: number of rows (values of ``i``) and columns (values of ``j``).

    Raises
    ------
    ZendarFormatError
        If a vector is not a finite 3-vector, ``di`` and ``dj`` are zero or parallel,
        or ``shape`` is not two positive integers. All problems are listed at once.
    """

    origin: np.ndarray
    di: np.ndarray
    dj: np.ndarray
    shape: tuple[int, int]

    def __post_init__(self) -> None:
        problems: list[str] = []
        origin = _vector3("origin", self.origin, problems)
        di = _vector3("di", self.di, problems)
        dj = _vector3("dj", self.dj, problems)
        shape = tuple(self.shape) if np.ndim(self.shape) == 1 else ()
        if len(shape) != 2 or not all(
            isinstance(n, (int, np.integer)) and not isinstance(n, bool) and n > 0 for n in shape
        ):
            problems.append(f"shape must be two positive integers (H, W), got {self.shape!r}")
            shape = (1, 1)
        norm_i, norm_j = np.linalg.norm(di), np.linalg.norm(dj)
        if norm_i == 0 or norm_j == 0:
            problems.append(f"di and dj must be non-zero, got di={di.tolist()}, dj={dj.tolist()}")
        elif np.linalg.norm(np.cross(di, dj)) < _MIN_SIN_ANGLE * norm_i * norm_j:
            problems.append(f"di and dj must not be parallel, got di={di.tolist()}, dj={dj.tolist()}")
        if problems:
            raise ZendarFormatError("invalid SAR image grid: " + "; ".join(problems), problems)
        for name, value in (("origin", origin), ("di", di), ("dj", dj)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "shape", (int(shape[0]), int(shape[1])))

    @classmethod
    def axis_aligned(
        cls,
        center: Any,
        u: Any,
        v: Any,
        pixel_m: float | tuple[float, float],
        shape: tuple[int, int],
    ) -> ImageGrid:
        """A grid centred on a point, rows along ``u`` and columns along ``v``.

        Parameters
        ----------
        center : array_like, shape (3,)
            World position of the image centre (between pixels when a side is even).
        u : array_like, shape (3,)
            Direction of +i, e.g. east. Only its direction is used.
        v : array_like, shape (3,)
            Direction of +j, e.g. north. Its component along ``u`` is removed so the
            pixels are square (or rectangular) in the world.
        pixel_m : float or (float, float)
            Pixel size in metres along ``i`` and ``j``.
        shape : (int, int)
            ``(H, W)``.
        """
        u = np.asarray(u, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        pixel_i_m, pixel_j_m = np.broadcast_to(np.asarray(pixel_m, dtype=np.float64), (2,))
        if not (pixel_i_m > 0 and pixel_j_m > 0):
            raise ZendarFormatError(f"pixel_m must be positive, got {pixel_m!r}")
        if u.shape != (3,) or v.shape != (3,) or np.linalg.norm(u) == 0:
            raise ZendarFormatError(
                f"u and v must be non-zero 3-vectors, got u={u.tolist()}, v={v.tolist()}"
            )
        u_unit = u / np.linalg.norm(u)
        v_perp = v - (v @ u_unit) * u_unit
        if np.linalg.norm(v_perp) < _MIN_SIN_ANGLE * max(np.linalg.norm(v), 1.0):
            raise ZendarFormatError(f"u and v must not be parallel, got u={u.tolist()}, v={v.tolist()}")
        v_unit = v_perp / np.linalg.norm(v_perp)
        di = pixel_i_m * u_unit
        dj = pixel_j_m * v_unit
        height, width = shape
        origin = np.asarray(center, dtype=np.float64) - (height - 1) / 2 * di - (width - 1) / 2 * dj
        return cls(origin=origin, di=di, dj=dj, shape=shape)

    @property
    def center(self) -> np.ndarray:
        """World position of the image centre, shape (3,), float64."""
        height, width = self.shape
        return self.origin + (height - 1) / 2 * self.di + (width - 1) / 2 * self.dj

    @property
    def normal(self) -> np.ndarray:
        """Unit normal of the image plane, ``di × dj`` normalised, shape (3,)."""
        n = np.cross(self.di, self.dj)
        return n / np.linalg.norm(n)

    def pixel_to_world(self, i: Any, j: Any) -> np.ndarray:
        """World positions of (fractional) pixel coordinates.

        Parameters
        ----------
        i, j : array_like
            Pixel coordinates, broadcast against each other, any shape ``S``.

        Returns
        -------
        numpy.ndarray, shape S + (3,), float64
        """
        i = np.asarray(i, dtype=np.float64)[..., None]
        j = np.asarray(j, dtype=np.float64)[..., None]
        return self.origin + i * self.di + j * self.dj

    def world_to_pixel(self, points: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pixel coordinates of world points, by least squares on the image plane.

        Parameters
        ----------
        points : array_like, shape S + (3,)
            Points in the grid's frame, metres.

        Returns
        -------
        i, j : numpy.ndarray, shape S, float64
            Fractional pixel coordinates of the points' projection onto the plane
            (not rounded, not clipped to the image).
        out_of_plane_m : numpy.ndarray, shape S, float64
            Signed distance from the plane along :attr:`normal`.
        """
        points = np.asarray(points, dtype=np.float64)
        if points.shape[-1:] != (3,):
            raise ValueError(f"points must have shape (..., 3), got {points.shape}")
        basis = np.stack([self.di, self.dj], axis=1)  # [3, 2]
        offsets = points - self.origin
        # Normal equations of the 2x2 system; exact for non-orthogonal di, dj too.
        gram = basis.T @ basis
        ij = np.linalg.solve(gram, (offsets @ basis)[..., None])[..., 0]
        out_of_plane_m = offsets @ self.normal
        return ij[..., 0], ij[..., 1], out_of_plane_m

    def pixel_centers(self) -> np.ndarray:
        """World positions of all pixels, shape ``(H, W, 3)``, float64."""
        height, width = self.shape
        return self.pixel_to_world(np.arange(height)[:, None], np.arange(width)[None, :])

    def transformed(self, transform: Any, translation: Any = None) -> ImageGrid:
        """The same grid expressed in another frame: ``p_new = R·p + t``.

        Parameters
        ----------
        transform : SE3-like, or array_like of shape (3, 3), or a scipy ``Rotation``
            Either a rigid transform ``new_T_grid`` with ``.rotation`` (3, 3) and
            ``.translation`` (3,) attributes (e.g. :class:`zendar_dataset.geometry.se3.SE3`
            ``ecef_T_enu``), or the rotation ``R`` alone, given with ``translation``.
        translation : array_like, shape (3,), optional
            Translation ``t`` in metres, when ``transform`` is a rotation.

        Returns
        -------
        ImageGrid
            Origin mapped as a point, ``di`` and ``dj`` rotated as vectors.
        """
        if translation is None:
            if not (hasattr(transform, "rotation") and hasattr(transform, "translation")):
                raise ValueError("give an SE3-like transform, or a rotation and a translation")
            matrix, translation = transform.rotation, transform.translation
        else:
            matrix = transform.as_matrix() if hasattr(transform, "as_matrix") else transform
        matrix = np.asarray(matrix, dtype=np.float64)
        translation = np.asarray(translation, dtype=np.float64)
        if matrix.shape != (3, 3) or translation.shape != (3,):
            raise ValueError(
                f"rotation must be (3, 3) and translation (3,), got {matrix.shape} and {translation.shape}"
            )
        return ImageGrid(
            origin=matrix @ self.origin + translation,
            di=matrix @ self.di,
            dj=matrix @ self.dj,
            shape=self.shape,
        )
