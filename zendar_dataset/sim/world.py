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

from zendar_dataset.sim.bodies import boxes_overlap
from zendar_dataset.sim.rotate import rotate
from zendar_dataset.sim.trajectory import Trajectory

ROAD_STEP_M = 0.05

# The street's cross section, lateral offsets from the ego lane's centre (left positive): the ego
# lane and the oncoming lane (3.5 m, a US urban arterial lane), a parallel-parking strip beyond
# each (NACTO Urban Street Design Guide: 7-9 ft, 2.1-2.7 m), a 0.3 m curb, a sidewalk of 2.5-4.5 m
# (NACTO: 5-12 ft plus a furniture zone) whose poles and trees stand 0.6 m behind the curb, then
# the facades.  Parked cars (<= 1.9 m wide) fit their strip; moving cars (<= 1.95 m) their lane.
LANE_WIDTH_M = 3.5
PARKING_WIDTH_M = 2.4
CURB_WIDTH_M = 0.3
SIDEWALK_WIDTH_M = (2.5, 4.5)
FURNITURE_OFFSET_M = 0.6
# A cross street (two 3.5 m lanes, sidewalks and corner radii) keeps this much arc length clear of
# static bodies on both sides of the road, centred on the intersection.
INTERSECTION_HALF_WIDTH_M = 11.0

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


# How a scatterer's RCS depends on where it is seen from (clutter.view_gains): a point keeps its RCS;
# a ground cell's is times sin(grazing angle), a wall cell's times cos²(incidence from its normal).
SURFACE_POINT, SURFACE_GROUND, SURFACE_WALL = 0, 1, 2

# Diffuse backscatter of the street's surfaces other than the ground (docs/simulator.md, sources):
# building walls are Lambertian, sigma0 = 4 S² cos²(incidence), with scattering coefficient S; tree
# canopies scatter from their volume, sigma0 per projected area the same from every side.
WALL_SCATTERING = 0.3
VEGETATION_SIGMA0_DB = -10.0
# The facade's cells: each point of a row stands for the wall between the rows (0-0.8, 0.8-1.7, 1.7-2.7 m).
FACADE_ROWS_M = np.array([0.4, 1.2, 2.2])
FACADE_ROW_HEIGHT_M = 0.9


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
    owner_box : numpy.ndarray or None
        ``[S]`` int64 index of the static box the scatterer lies on or in, which therefore does not
        hide it (a facade's wall, a pole); -1 (or None for all) where every box may hide it.
    surface : numpy.ndarray or None
        ``[S]`` int8 ``SURFACE_*``: a point, or a cell of the ground or of a wall whose RCS
        (``rcs_m2`` at normal view) depends on the viewing direction; None: all points.
    normal : numpy.ndarray or None
        ``[S, 3]`` outward unit normal of wall cells (zero elsewhere); None: all zero.
    """

    position_m: np.ndarray
    rcs_m2: np.ndarray
    swerling1: np.ndarray
    phase_rad: np.ndarray
    owner_box: np.ndarray | None = None
    surface: np.ndarray | None = None
    normal: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = self.position_m.shape[0]
        if self.owner_box is None:
            self.owner_box = np.full(n, -1, np.int64)
        if self.surface is None:
            self.surface = np.full(n, SURFACE_POINT, np.int8)
        if self.normal is None:
            self.normal = np.zeros((n, 3))
        vectors = (self.rcs_m2, self.swerling1, self.phase_rad, self.owner_box, self.surface)
        if self.position_m.shape != (n, 3) or self.normal.shape != (n, 3) or any(a.shape != (n,) for a in vectors):
            raise ValueError("scatterer arrays must be [S, 3], [S], [S], [S], [S], [S], [S, 3]")

    @classmethod
    def empty(cls) -> ScattererSet:
        return cls(np.zeros((0, 3)), np.zeros(0), np.zeros(0, bool), np.zeros(0), np.zeros(0, np.int64))

    def subset(self, which: np.ndarray) -> ScattererSet:
        """The scatterers selected by ``which`` (a boolean mask or indices)."""
        return ScattererSet(self.position_m[which], self.rcs_m2[which], self.swerling1[which], self.phase_rad[which],
                            self.owner_box[which], self.surface[which], self.normal[which])

    @classmethod
    def concatenate(cls, sets: list[ScattererSet]) -> ScattererSet:
        sets = [s for s in sets if s.position_m.shape[0]] or [cls.empty()]
        return cls(
            np.concatenate([s.position_m for s in sets]),
            np.concatenate([s.rcs_m2 for s in sets]),
            np.concatenate([s.swerling1 for s in sets]),
            np.concatenate([s.phase_rad for s in sets]),
            np.concatenate([s.owner_box for s in sets]),
            np.concatenate([s.surface for s in sets]),
            np.concatenate([s.normal for s in sets]),
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
    """Everything in a scene except the ego vehicle.

    ``intersections_s``: arc lengths (m) of the cross streets, kept clear of static bodies.
    """

    road: Road
    static_boxes: BoxSet
    static_scatterers: ScattererSet
    cars: list[MovingCar] = field(default_factory=list)
    intersections_s: list[float] = field(default_factory=list)

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


def street_edge_m(side: float) -> float:
    """Lateral offset (m) of the road edge, the outer side of the parking strip, on ``side`` (+1 left, -1 right)."""
    if side > 0:
        return LANE_WIDTH_M * 1.5 + PARKING_WIDTH_M
    return -(LANE_WIDTH_M / 2 + PARKING_WIDTH_M)


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


class _Placer:
    """Static bodies placed so far; a candidate that would overlap one of them is refused."""

    def __init__(self) -> None:
        self.boxes: list[BoxSet] = []
        self.scatterers: list[ScattererSet] = []
        self._center: list[np.ndarray] = []
        self._size: list[np.ndarray] = []
        self._yaw: list[float] = []

    def fits(self, box: BoxSet) -> bool:
        if not self._center:
            return True
        return not np.any(boxes_overlap(box.center_enu[0], box.size_m[0], box.yaw_rad[0],
                                        np.array(self._center), np.array(self._size), np.array(self._yaw)))

    def add(self, box: BoxSet, scatterers: ScattererSet | None = None, *, owns_scatterers: bool = True) -> bool:
        """Place ``box`` (and its scatterers) unless it overlaps a placed body; returns whether it was placed.

        ``owns_scatterers``: the scatterers lie on or inside this box (a facade's wall, a pole), so
        the box does not hide them from a sensor; a car's scatterers are on its surface and its
        own body does hide those on its far side, so they are placed without an owner.
        """
        if not self.fits(box):
            return False
        index = sum(b.center_enu.shape[0] for b in self.boxes)
        self.boxes.append(box)
        self._center.append(box.center_enu[0])
        self._size.append(box.size_m[0])
        self._yaw.append(float(box.yaw_rad[0]))
        if scatterers is not None:
            n = scatterers.position_m.shape[0]
            scatterers.owner_box = np.full(n, index if owns_scatterers else -1, np.int64)
            self.scatterers.append(scatterers)
        return True


def _in_gap(s_lo: float, s_hi: float, gaps_s: list[tuple[float, float]]) -> tuple[float, float] | None:
    for lo, hi in gaps_s:
        if s_lo < hi and s_hi > lo:
            return lo, hi
    return None


def build_static_world(
    rng: np.random.Generator,
    road: Road,
    s_start_m: float,
    s_end_m: float,
    facade_spacing_m: float,
    gaps_s: list[tuple[float, float]] = (),
) -> tuple[BoxSet, ScattererSet, tuple[float, float]]:
    """Facades, parked cars, poles, trees, curbs and guard rails along both sides of ``road``.

    The cross section (lateral offsets from the ego lane's centre, left positive) is
    :func:`street_edges`: the two lanes, a parking strip beyond each, a curb, a sidewalk with
    poles and trees, then the facades.  Nothing is placed over the arc-length intervals
    ``gaps_s`` (cross streets), and no body overlaps another (on a curve, a block that would
    overlap its neighbour is left out).

    Returns
    -------
    boxes : BoxSet
        The static boxes.
    scatterers : ScattererSet
        Their scatterers, ENU; ``owner_box`` indexes ``boxes`` (or -1, see :meth:`_Placer.add`).
    ground_m : (float, float)
        Lateral offsets of the right and the left facade: the ground between them (road, curbs and
        sidewalks) is the street's open surface.
    """
    placer = _Placer()
    facades = {}
    for side in (1.0, -1.0):
        edge = street_edge_m(side)  # lateral offset of the road edge (inner face of the curb)
        sidewalk = rng.uniform(*SIDEWALK_WIDTH_M)
        facade = side * (abs(edge) + CURB_WIDTH_M + sidewalk)
        facades[side] = facade
        guard_rail = rng.random() < 0.25
        s = s_start_m
        while s < s_end_m:
            length = rng.uniform(8.0, 25.0)
            gap = _in_gap(s, s + length, list(gaps_s))
            if gap is not None:
                s = gap[1] + rng.uniform(0.5, 4.0)
                continue
            mid = s + length / 2
            pos, yaw = road.point(mid, facade)
            tangent = np.array([np.cos(yaw), np.sin(yaw), 0.0])
            normal = np.array([-np.sin(yaw), np.cos(yaw), 0.0]) * side
            depth, height = 6.0, rng.uniform(6.0, 15.0)
            start = pos - tangent * length / 2
            pts = _face_points(start, tangent, length, facade_spacing_m, FACADE_ROWS_M)
            pts[:, :2] += rng.normal(0, 0.03, (pts.shape[0], 2))
            # Diffuse wall cells: Lambertian at normal view times a log-normal factor of unit mean (the
            # heavy tail of urban clutter), fluctuating from frame to frame as the view moves, seen
            # off-normal through clutter.view_gains.
            speckle = rng.lognormal(0.0, 1.0, pts.shape[0]) / np.exp(0.5)
            rcs = 4.0 * WALL_SCATTERING**2 * facade_spacing_m * FACADE_ROW_HEIGHT_M * speckle
            strong = rng.random(pts.shape[0]) < 0.05  # window frames, door recesses: corner reflectors
            rcs[strong] = rng.uniform(2.0, 10.0, strong.sum())
            wall = _scatterers(rng, pts, rcs, ~strong)
            wall.surface = np.where(strong, SURFACE_POINT, SURFACE_WALL).astype(np.int8)
            wall.normal = np.where(strong[:, None], 0.0, -normal[None, :])
            placer.add(_box(pos + normal * depth / 2 + [0, 0, height / 2], (length, depth, height), yaw, COLORS["building"]),
                       wall)
            # Curb along the block, just outside the road edge.
            cpos, _ = road.point(mid, side * (abs(edge) + CURB_WIDTH_M / 2))
            cpts = _face_points(cpos - tangent * length / 2, tangent, length, 0.5, np.array([0.1]))
            placer.add(_box(cpos + [0, 0, 0.075], (length, CURB_WIDTH_M, 0.15), yaw, COLORS["curb"]),
                       _scatterers(rng, cpts, rng.lognormal(np.log(0.02), 0.5, cpts.shape[0]), np.ones(cpts.shape[0], bool)))
            if guard_rail:
                # A rail on the sidewalk, behind the curb (its posts stand 0.2 m back).
                rpos, _ = road.point(mid, side * (abs(edge) + CURB_WIDTH_M + 0.2))
                rpts = _face_points(rpos - tangent * length / 2, tangent, length, 0.3, np.array([0.6]))
                placer.add(_box(rpos + [0, 0, 0.6], (length, 0.1, 0.3), yaw, COLORS["rail"]),
                           _scatterers(rng, rpts, rng.lognormal(np.log(0.2), 0.5, rpts.shape[0]), np.ones(rpts.shape[0], bool)))
            else:
                # Parked cars in the parking strip, centred in it.
                along = s + rng.uniform(0.5, 3.0)
                while along < s + length - 4.5:
                    if rng.random() < 0.6:
                        size = np.array([rng.uniform(4.0, 4.9), rng.uniform(1.7, 1.9), rng.uniform(1.4, 1.6)])
                        ppos, pyaw = road.point(along + size[0] / 2, side * (abs(edge) - PARKING_WIDTH_M / 2))
                        body = car_scatterers(rng, size)
                        c, sn = np.cos(pyaw), np.sin(pyaw)
                        rot = np.array([[c, -sn, 0], [sn, c, 0], [0, 0, 1]])
                        body.position_m = rotate(rot, body.position_m) + ppos
                        placer.add(_box(ppos + [0, 0, size[2] / 2], size, pyaw, COLORS["parked_car"]), body, owns_scatterers=False)
                    along += rng.uniform(5.5, 8.0)
            # Poles and trees in the sidewalk's furniture zone.
            for s_obj in np.arange(s + rng.uniform(0, 10.0), s + length, rng.uniform(10.0, 20.0)):
                opos, oyaw = road.point(s_obj, side * (abs(edge) + CURB_WIDTH_M + FURNITURE_OFFSET_M))
                if rng.random() < 0.5:
                    pts = opos + np.array([[0, 0, 0.5], [0, 0, 1.5]])
                    placer.add(_box(opos + [0, 0, 2.5], (0.25, 0.25, 5.0), oyaw, COLORS["pole"]),
                               _scatterers(rng, pts, np.array([0.5, 0.5]), np.zeros(2, bool)))
                else:
                    trunk_top = 2.75  # where the canopy starts: trunk and canopy are one body
                    pts = opos + np.concatenate([[[0, 0, 0.8]], rng.uniform([-1.5, -1.5, 2.8], [1.5, 1.5, 5.0], (4, 3))])
                    trunk = _box(opos + [0, 0, trunk_top / 2], (0.4, 0.4, trunk_top), oyaw, COLORS["trunk"])
                    canopy = _box(opos + [0, 0, trunk_top + 1.25], (3.0, 3.0, 2.5), oyaw, COLORS["canopy"])
                    if placer.fits(trunk) and placer.fits(canopy):
                        placer.add(trunk, _scatterers(rng, pts[:1], np.array([0.3]), np.ones(1, bool)))
                        # The canopy's volume return: sigma0 times its side's area (3 m by 2.5 m), over 4 points.
                        canopy_rcs = 10.0 ** (VEGETATION_SIGMA0_DB / 10.0) * 3.0 * 2.5 / 4
                        placer.add(canopy, _scatterers(rng, pts[1:], np.full(4, canopy_rcs), np.ones(4, bool)))
            s += length + (rng.uniform(12.0, 16.0) if rng.random() < 0.15 else rng.uniform(0.5, 4.0))
    return BoxSet.concatenate(placer.boxes), ScattererSet.concatenate(placer.scatterers), (facades[-1.0], facades[1.0])
