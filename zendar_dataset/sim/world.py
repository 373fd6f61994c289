"""The simulated world: a street in a local ENU frame, with its objects.

Every object is a box (for lidar, camera and labels) plus a set of point
scatterers (for the radars).  Static objects are placed along the road
(building facades, parked cars, poles, trees, curbs, guard rails); moving cars
(:mod:`zendar_dataset.sim.traffic`) carry their scatterers in their own body
frame (x forward, y left, z up, origin on the ground under the box centre).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from zendar_dataset.sim.rotate import rotate
from zendar_dataset.sim.trajectory import Trajectory

ROAD_STEP_M = 0.05
LANE_WIDTH_M = 3.5
CURB_OFFSET_M = 5.5

# Colours (RGB) used by the camera.
COLORS = {
    "building": (170, 150, 130),
    "car": (40, 70, 160),
    "parked_car": (120, 30, 30),
    "pole": (90, 90, 90),
    "trunk": (100, 70, 40),
    "canopy": (40, 120, 40),
    "curb": (200, 200, 200),
    "rail": (180, 180, 190),
}


@dataclass(frozen=True)
class Road:
    """The road's reference line (the ego lane's centre), sampled along its arc length.

    Attributes
    ----------
    s_m : numpy.ndarray
        ``[K]`` arc length, metres (uniform steps of :data:`ROAD_STEP_M`).
    xy_enu : numpy.ndarray
        ``[K, 2]`` east, north, metres.
    yaw_rad : numpy.ndarray
        ``[K]`` direction of travel, counter-clockwise from east.
    """

    s_m: np.ndarray
    xy_enu: np.ndarray
    yaw_rad: np.ndarray

    @classmethod
    def from_curvature(cls, s_start_m: float, s_end_m: float, curvature_at) -> Road:
        s = np.arange(s_start_m, s_end_m + ROAD_STEP_M, ROAD_STEP_M)
        kappa = curvature_at(s)
        origin = int(np.argmin(np.abs(s)))
        yaw = np.concatenate([[0.0], np.cumsum(0.5 * (kappa[1:] + kappa[:-1]) * ROAD_STEP_M)])
        yaw -= yaw[origin]
        mid = 0.5 * (yaw[1:] + yaw[:-1])
        x = np.concatenate([[0.0], np.cumsum(ROAD_STEP_M * np.cos(mid))])
        y = np.concatenate([[0.0], np.cumsum(ROAD_STEP_M * np.sin(mid))])
        xy = np.stack([x - x[origin], y - y[origin]], axis=1)
        return cls(s, xy, yaw)

    def point(self, s_m: np.ndarray, lateral_m: np.ndarray | float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """ENU position ``[..., 3]`` (on the ground) and yaw ``[...]`` at arc length ``s`` and left offset."""
        s = np.asarray(s_m, dtype=np.float64)
        pos = np.clip((s - self.s_m[0]) / ROAD_STEP_M, 0.0, self.s_m.shape[0] - 1.000001)
        lower = pos.astype(np.int64)
        frac = pos - lower
        xy = self.xy_enu[lower] * (1 - frac[..., None]) + self.xy_enu[lower + 1] * frac[..., None]
        yaw = self.yaw_rad[lower] * (1 - frac) + self.yaw_rad[lower + 1] * frac
        lateral = np.asarray(lateral_m, dtype=np.float64)
        east = xy[..., 0] - np.sin(yaw) * lateral
        north = xy[..., 1] + np.cos(yaw) * lateral
        return np.stack([east, north, np.zeros_like(east)], axis=-1), yaw


@dataclass
class ScattererSet:
    """Point scatterers: position (world or body frame), RCS, fluctuation model, phase.

    Attributes
    ----------
    position_m : numpy.ndarray
        ``[S, 3]`` float64 metres.
    rcs_m2 : numpy.ndarray
        ``[S]`` mean radar cross-section, m^2.
    swerling1 : numpy.ndarray
        ``[S]`` bool: the return fluctuates frame to frame (Swerling 1: Rayleigh
        amplitude, uniform phase); otherwise it is steady (Swerling 0).
    phase_rad : numpy.ndarray
        ``[S]`` fixed reflection phase of steady scatterers.
    """

    position_m: np.ndarray
    rcs_m2: np.ndarray
    swerling1: np.ndarray
    phase_rad: np.ndarray

    def __post_init__(self) -> None:
        n = self.position_m.shape[0]
        if self.position_m.shape != (n, 3) or any(a.shape != (n,) for a in (self.rcs_m2, self.swerling1, self.phase_rad)):
            raise ValueError("scatterer arrays must be [S, 3], [S], [S], [S]")

    @classmethod
    def empty(cls) -> ScattererSet:
        return cls(np.zeros((0, 3)), np.zeros(0), np.zeros(0, bool), np.zeros(0))

    @classmethod
    def concatenate(cls, sets: list[ScattererSet]) -> ScattererSet:
        sets = [s for s in sets if s.position_m.shape[0]] or [cls.empty()]
        return cls(
            np.concatenate([s.position_m for s in sets]),
            np.concatenate([s.rcs_m2 for s in sets]),
            np.concatenate([s.swerling1 for s in sets]),
            np.concatenate([s.phase_rad for s in sets]),
        )


@dataclass
class BoxSet:
    """Oriented boxes standing on the ground.

    Attributes
    ----------
    center_enu : numpy.ndarray
        ``[B, 3]`` box centre (z is half the height above the box's base), metres.
    size_m : numpy.ndarray
        ``[B, 3]`` length (along yaw), width, height, metres.
    yaw_rad : numpy.ndarray
        ``[B]`` heading of the length axis.
    color : numpy.ndarray
        ``[B, 3]`` uint8 RGB.
    track_id : numpy.ndarray
        ``[B]`` int64, the moving car's track, -1 for static objects.
    """

    center_enu: np.ndarray
    size_m: np.ndarray
    yaw_rad: np.ndarray
    color: np.ndarray
    track_id: np.ndarray

    @classmethod
    def concatenate(cls, sets: list[BoxSet]) -> BoxSet:
        return cls(
            np.concatenate([s.center_enu for s in sets]).reshape(-1, 3),
            np.concatenate([s.size_m for s in sets]).reshape(-1, 3),
            np.concatenate([s.yaw_rad for s in sets]),
            np.concatenate([s.color for s in sets]).reshape(-1, 3).astype(np.uint8),
            np.concatenate([s.track_id for s in sets]).astype(np.int64),
        )


@dataclass
class MovingCar:
    """A moving car: its track, trajectory, box size and body-frame scatterers."""

    track_id: int
    trajectory: Trajectory
    size_m: np.ndarray
    scatterers_body: ScattererSet
    color: tuple[int, int, int] = COLORS["car"]


@dataclass
class World:
    """Everything in a scene except the ego vehicle."""

    road: Road
    static_boxes: BoxSet
    static_scatterers: ScattererSet
    cars: list[MovingCar] = field(default_factory=list)

    def boxes_at(self, t_s: float) -> BoxSet:
        """Static boxes plus every moving car's box at time ``t_s``."""
        if not self.cars:
            return self.static_boxes
        t = np.asarray(t_s, dtype=np.float64)
        centers = np.stack([c.trajectory.position_at(t) for c in self.cars])
        sizes = np.stack([c.size_m for c in self.cars])
        centers[:, 2] = sizes[:, 2] / 2
        moving = BoxSet(
            centers,
            sizes,
            np.array([float(c.trajectory.yaw_at(t)) for c in self.cars]),
            np.array([c.color for c in self.cars], dtype=np.uint8),
            np.array([c.track_id for c in self.cars], dtype=np.int64),
        )
        return BoxSet.concatenate([self.static_boxes, moving])

    def moving_scatterers(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, ScattererSet, np.ndarray]:
        """Positions and velocities of every moving car's scatterers at times ``[M]``.

        Returns
        -------
        position_enu : numpy.ndarray
            ``[S, M, 3]`` metres.
        velocity_enu : numpy.ndarray
            ``[S, M, 3]`` m/s (rigid-body motion, including the yaw rate).
        scatterers : ScattererSet
            Their RCS, fluctuation flags and phases (positions in body frames).
        track_id : numpy.ndarray
            ``[S]`` int64.
        """
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        positions, velocities, ids = [], [], []
        for car in self.cars:
            body = car.scatterers_body.position_m  # [Sc, 3]
            yaw = car.trajectory.yaw_at(t)  # [M]
            c, s = np.cos(yaw), np.sin(yaw)
            x = c[None, :] * body[:, 0:1] - s[None, :] * body[:, 1:2]  # [Sc, M]
            y = s[None, :] * body[:, 0:1] + c[None, :] * body[:, 1:2]
            origin = car.trajectory.position_at(t)  # [M, 3]
            pos = np.stack([x, y, np.broadcast_to(body[:, 2:3], x.shape)], axis=-1) + origin[None]
            rate = car.trajectory.yaw_rate_at(t)[None, :]
            vel = car.trajectory.velocity_at(t)[None] + np.stack([-rate * y, rate * x, np.zeros_like(x)], axis=-1)
            positions.append(pos)
            velocities.append(vel)
            ids.append(np.full(body.shape[0], car.track_id, dtype=np.int64))
        if not positions:
            empty = np.zeros((0, t.shape[0], 3))
            return empty, empty, ScattererSet.empty(), np.zeros(0, np.int64)
        return (
            np.concatenate(positions),
            np.concatenate(velocities),
            ScattererSet.concatenate([c.scatterers_body for c in self.cars]),
            np.concatenate(ids),
        )


def _scatterers(rng: np.random.Generator, position: np.ndarray, rcs_m2: np.ndarray, swerling1: np.ndarray) -> ScattererSet:
    n = position.shape[0]
    return ScattererSet(position.reshape(n, 3), rcs_m2.reshape(n), swerling1.reshape(n), rng.uniform(0, 2 * np.pi, n))


def car_scatterers(rng: np.random.Generator, size_m: np.ndarray) -> ScattererSet:
    """Body-frame scatterers of a car: corners, bumpers, wheel houses, mirrors, a plate."""
    half_l, half_w = size_m[0] / 2, size_m[1] / 2
    points = [
        (half_l, half_w, 0.5), (half_l, -half_w, 0.5), (-half_l, half_w, 0.5), (-half_l, -half_w, 0.5),
        (half_l, 0.0, 0.45), (-half_l, 0.0, 0.55),
        (0.6 * half_l, half_w, 0.35), (0.6 * half_l, -half_w, 0.35),
        (-0.6 * half_l, half_w, 0.35), (-0.6 * half_l, -half_w, 0.35),
        (0.4 * half_l, half_w + 0.1, 1.0), (0.4 * half_l, -half_w - 0.1, 1.0),
        (0.0, half_w, 0.8), (0.0, -half_w, 0.8), (-half_l, 0.0, 0.9),
    ]
    position = np.array(points, dtype=np.float64)
    rcs = rng.lognormal(np.log(0.8), 0.7, position.shape[0])
    swerling1 = np.ones(position.shape[0], bool)
    swerling1[[4, 5, 14]] = False  # plates and bumper centres are steady specular returns
    rcs[[4, 5]] *= 4.0
    return _scatterers(rng, position, rcs, swerling1)


def _box(center, size, yaw, color, track_id=-1) -> BoxSet:
    return BoxSet(
        np.asarray(center, np.float64).reshape(1, 3), np.asarray(size, np.float64).reshape(1, 3),
        np.array([yaw], np.float64), np.array([color], np.uint8), np.array([track_id], np.int64),
    )


def _face_points(origin: np.ndarray, along: np.ndarray, length: float, spacing: float, heights: np.ndarray) -> np.ndarray:
    """Points every ``spacing`` along a segment, at each height."""
    steps = np.arange(spacing / 2, length, spacing)
    base = origin[None, :] + steps[:, None] * along[None, :]
    pts = np.repeat(base[:, None, :], heights.shape[0], axis=1)
    pts[..., 2] = heights[None, :]
    return pts.reshape(-1, 3)


def build_static_world(rng: np.random.Generator, road: Road, s_start_m: float, s_end_m: float, facade_spacing_m: float) -> tuple[BoxSet, ScattererSet]:
    """Facades, parked cars, poles, trees, curbs and guard rails along both sides of ``road``."""
    boxes: list[BoxSet] = []
    scatterers: list[ScattererSet] = []
    for side in (1.0, -1.0):
        # Own lane at 0, oncoming lane at +LANE_WIDTH_M: the left curb is further out.
        curb = CURB_OFFSET_M if side > 0 else LANE_WIDTH_M / 2 + 0.3
        facade = curb + rng.uniform(3.0, 5.0)
        guard_rail = rng.random() < 0.25
        s = s_start_m
        while s < s_end_m:
            length = rng.uniform(8.0, 25.0)
            mid = s + length / 2
            pos, yaw = road.point(mid, side * facade)
            tangent = np.array([np.cos(yaw), np.sin(yaw), 0.0])
            normal = np.array([-np.sin(yaw), np.cos(yaw), 0.0]) * side
            depth, height = 6.0, rng.uniform(6.0, 15.0)
            boxes.append(_box(pos + normal * depth / 2 + [0, 0, height / 2], (length, depth, height), yaw, COLORS["building"]))
            start = pos - tangent * length / 2
            pts = _face_points(start, tangent, length, facade_spacing_m, np.array([0.4, 1.2, 2.2]))
            pts[:, :2] += rng.normal(0, 0.03, (pts.shape[0], 2))
            rcs = rng.lognormal(np.log(0.05), 1.0, pts.shape[0])
            strong = rng.random(pts.shape[0]) < 0.05  # window frames, door recesses: corner reflectors
            rcs[strong] = rng.uniform(2.0, 10.0, strong.sum())
            scatterers.append(_scatterers(rng, pts, rcs, ~strong))
            # Curb in front of the facade block.
            cpos, _ = road.point(mid, side * curb)
            boxes.append(_box(cpos + [0, 0, 0.075], (length, 0.3, 0.15), yaw, COLORS["curb"]))
            cpts = _face_points(cpos - tangent * length / 2, tangent, length, 0.5, np.array([0.1]))
            scatterers.append(_scatterers(rng, cpts, rng.lognormal(np.log(0.02), 0.5, cpts.shape[0]), np.ones(cpts.shape[0], bool)))
            if guard_rail:
                rpos, _ = road.point(mid, side * (curb - 0.3))
                boxes.append(_box(rpos + [0, 0, 0.6], (length, 0.1, 0.3), yaw, COLORS["rail"]))
                rpts = _face_points(rpos - tangent * length / 2, tangent, length, 0.3, np.array([0.6]))
                scatterers.append(_scatterers(rng, rpts, rng.lognormal(np.log(0.2), 0.5, rpts.shape[0]), np.ones(rpts.shape[0], bool)))
            else:
                # Parked cars along the curb.
                along = s + rng.uniform(0.5, 3.0)
                while along < s + length - 4.5:
                    if rng.random() < 0.6:
                        size = np.array([rng.uniform(4.0, 4.9), rng.uniform(1.7, 1.9), rng.uniform(1.4, 1.6)])
                        ppos, pyaw = road.point(along + size[0] / 2, side * (curb - 1.2))
                        boxes.append(_box(ppos + [0, 0, size[2] / 2], size, pyaw, COLORS["parked_car"]))
                        body = car_scatterers(rng, size)
                        c, sn = np.cos(pyaw), np.sin(pyaw)
                        rot = np.array([[c, -sn, 0], [sn, c, 0], [0, 0, 1]])
                        body.position_m = rotate(rot, body.position_m) + ppos
                        scatterers.append(body)
                    along += rng.uniform(5.5, 8.0)
            # Poles and trees on the sidewalk.
            for s_obj in np.arange(s + rng.uniform(0, 10.0), s + length, rng.uniform(10.0, 20.0)):
                opos, oyaw = road.point(s_obj, side * (curb + 1.0))
                if rng.random() < 0.5:
                    boxes.append(_box(opos + [0, 0, 2.5], (0.25, 0.25, 5.0), oyaw, COLORS["pole"]))
                    pts = opos + np.array([[0, 0, 0.5], [0, 0, 1.5]])
                    scatterers.append(_scatterers(rng, pts, np.array([0.5, 0.5]), np.zeros(2, bool)))
                else:
                    boxes.append(_box(opos + [0, 0, 1.5], (0.4, 0.4, 3.0), oyaw, COLORS["trunk"]))
                    boxes.append(_box(opos + [0, 0, 4.0], (3.0, 3.0, 2.5), oyaw, COLORS["canopy"]))
                    pts = opos + np.concatenate([[[0, 0, 0.8]], rng.uniform([-1.5, -1.5, 2.8], [1.5, 1.5, 5.0], (4, 3))])
                    scatterers.append(_scatterers(rng, pts, np.array([0.3, 0.05, 0.05, 0.05, 0.05]), np.ones(5, bool)))
            s += length + (rng.uniform(12.0, 16.0) if rng.random() < 0.15 else rng.uniform(0.5, 4.0))
    return BoxSet.concatenate(boxes), ScattererSet.concatenate(scatterers)
