"""One synthetic scene, end to end, written through a format-v1 ``SceneWriter``.

Random streams: every stream (world, traffic, ego, tracklog noise, each radar's
noise and fluctuation, lidar, ...) draws from its own ``numpy.random.Generator``
seeded by ``(seed, scene_index, stream)``, so a scene's bytes depend on nothing
else (not on other scenes, the order of work, or the clock).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from zendar_dataset.geometry.geodesy import LocalENU
from zendar_dataset.geometry.poses import PoseInterpolator
from zendar_dataset.geometry.quaternion import quat_wxyz_to_matrix
from zendar_dataset.radar.range_doppler import range_doppler, range_profiles
from zendar_dataset.sim import camera as camera_model
from zendar_dataset.sim import ego as ego_model
from zendar_dataset.sim.clutter import road_clutter, view_gains
from zendar_dataset.sim.echoes import car_echoes
from zendar_dataset.sim.imperfections import Imperfections
from zendar_dataset.sim.imperfections import antenna_errors as channel_errors
from zendar_dataset.sim.labels import label_rows, radar_views
from zendar_dataset.sim.lidar import lidar_sweep
from zendar_dataset.sim.profiles import SimProfile
from zendar_dataset.sim.radar_model import RadarFrontEnd, synthesize_cube, synthesize_range_profiles, thermal_noise
from zendar_dataset.sim.raycast import line_of_sight
from zendar_dataset.sim.rotate import compose, dot, rotate, unrotate
from zendar_dataset.sim.sar_formation import (
    SarGeometry,
    aperture_times,
    chirps_per_pulse,
    form_image,
    presum_factors,
    pulse_spacing_m,
    sar_waveform,
)
from zendar_dataset.sim.traffic import make_traffic
from zendar_dataset.sim.trajectory import follow_road, speed_profile
from zendar_dataset.sim.world import (
    INTERSECTION_HALF_WIDTH_M,
    LANE_WIDTH_M,
    Road,
    ScattererSet,
    World,
    build_static_world,
)

GPS_EPOCH_START_NS = 1_300_000_000_000_000_000
PAD_S = 1.5
CUBE_HALF_WIDTH_BINS = 4
SAR_HALF_WIDTH_BINS = 4
SAR_MARGIN_M = 5.0
STREAMS = ("road", "ego", "world", "traffic", "tracklog", "front_left", "front_right", "sar_front_left",
           "sar_front_right", "lidar", "enu", "clocks", "clutter")

# Free-running sensors are not triggered together: each starts at its own phase within its frame
# period and its frame times jitter (camera trigger latency, lidar rotation, radar frame scheduling),
# so the loader's synchronisation has real residuals to measure, as on recorded data.
CLOCK_JITTER_S = {"radar": 20e-6, "lidar": 200e-6, "camera": 1e-3}


def stream_rng(seed: int, scene_index: int, stream: str) -> np.random.Generator:
    """The generator of one random stream of one scene."""
    return np.random.default_rng([int(seed), int(scene_index), STREAMS.index(stream)])


@dataclass
class SceneTruth:
    """What was simulated, kept in memory (not written): world, ego trajectory, true tracklog."""

    world: World
    ego: object
    tracklog_truth: ego_model.Tracklog
    tracklog_written: ego_model.Tracklog
    enu: LocalENU
    start_ns: int


def build_scene(profile: SimProfile, seed: int, scene_index: int) -> SceneTruth:
    """Draw the road, ego drive, world, traffic and tracklogs of one scene."""
    duration = profile.scene_duration_s
    rng = stream_rng(seed, scene_index, "road")
    turn = rng.random() < 0.5
    turn_start, turn_length = rng.uniform(5.0, 40.0), rng.uniform(15.0, 35.0)
    turn_kappa = rng.choice([-1.0, 1.0]) / rng.uniform(25.0, 60.0)
    road_rng = rng

    def curvature(s: np.ndarray) -> np.ndarray:
        return np.where(turn & (s > turn_start) & (s < turn_start + turn_length), turn_kappa, 0.0)

    rng = stream_rng(seed, scene_index, "ego")
    cruise = float(rng.uniform(5.0, 14.0))
    stops = [(float(rng.uniform(0.4, 0.6) * duration), float(rng.uniform(0.3, 1.0)))] if rng.random() < 0.3 else []
    time_s, speed = speed_profile(duration + 2 * PAD_S, cruise, [(s + PAD_S, w) for s, w in stops])
    time_s = time_s - PAD_S
    road_end = cruise * (duration + 2 * PAD_S) + 160.0
    road = Road.from_curvature(-120.0, road_end, curvature)
    ego = follow_road(road, time_s, speed, -cruise * PAD_S)

    ego_start_s = -cruise * PAD_S
    # Cross streets (where crossing and turning cars drive) every 60-150 m (city blocks) along the drive.
    intersections = [ego_start_s + float(road_rng.uniform(10.0, 30.0))]
    while intersections[-1] < ego_start_s + cruise * (duration + 2 * PAD_S) + 30.0:
        intersections.append(intersections[-1] + float(road_rng.uniform(60.0, 150.0)))
    gaps = [(s - INTERSECTION_HALF_WIDTH_M, s + INTERSECTION_HALF_WIDTH_M) for s in intersections]
    rng = stream_rng(seed, scene_index, "world")
    boxes, scatterers, ground_m = build_static_world(rng, road, ego_start_s - 40.0, road_end - 40.0,
                                                     profile.facade_spacing_m, gaps)
    # The ground from facade to facade (road and sidewalks), as clutter (its own stream: the world's draws
    # stay as they were).
    clutter = road_clutter(stream_rng(seed, scene_index, "clutter"), road, -cruise * PAD_S - 40.0, road_end - 40.0,
                           ground_m, profile.imperfections)
    scatterers = ScattererSet.concatenate([scatterers, clutter])
    rng = stream_rng(seed, scene_index, "traffic")
    n_cars = int(rng.integers(profile.n_moving_cars[0], profile.n_moving_cars[1] + 1))
    cars = make_traffic(
        rng, road, n_cars, -PAD_S, duration + 2 * PAD_S, ego_start_s, cruise,
        ego_boxes=lambda t: ego_model.ego_boxes(ego, t), static_boxes=boxes, intersections_s=intersections,
    )
    world = World(road, boxes, scatterers, cars, intersections)

    rng = stream_rng(seed, scene_index, "enu")
    enu = LocalENU(37.7749 + rng.uniform(-0.05, 0.05), -122.4194 + rng.uniform(-0.05, 0.05), 10.0)
    start_ns = GPS_EPOCH_START_NS + scene_index * 10**12
    truth, written = ego_model.make_tracklogs(
        ego, enu, start_ns, -PAD_S + 0.01, duration + PAD_S - 0.01, stream_rng(seed, scene_index, "tracklog")
    )
    return SceneTruth(world, ego, truth, written, enu, start_ns)


def _scatterers_in_sensor(truth: SceneTruth, sensor: str, t_s: np.ndarray, max_range_m: float, *,
                          effects: Imperfections, with_velocity: bool = False):
    """Scatterers within ``max_range_m`` in front of the sensor at the middle of ``t_s`` ``[M]``.

    Returns positions ``[S, M, 3]`` in the sensor frame at every time, their
    RCS, Swerling-1 flags and phases ``[S]``, and (``with_velocity``) their
    velocities relative to the sensor ``[S, M, 3]`` in the sensor frame.
    """
    m = t_s.shape[0]
    if with_velocity:
        # Positions 0.1 ms later give the relative velocity by a finite difference.
        t_s = np.concatenate([t_s, t_s + 1e-4])
    rotation, position = ego_model.sensor_poses_enu(truth.ego, sensor, t_s)  # [M, 3, 3], [M, 3]
    world = truth.world
    static = world.static_scatterers
    mid = m // 2
    moving_pos, _vel, moving, _ids = car_echoes(world, t_s, position[mid], effects, mid_index=mid, reach_m=max_range_m + 1.0)
    # Cull at the middle time first: transforming every scatterer at every time is the cost.
    static_mid = unrotate(rotation[mid], static.position_m - position[mid])
    reach = max_range_m + 1.0
    near = (static_mid[:, 0] > -1.0) & (np.linalg.norm(static_mid, axis=1) < reach)
    moving_near = np.linalg.norm(moving_pos[:, mid] - position[mid], axis=1) < reach
    # A return exists only where the path from the radar is clear at the middle time (the boxes
    # move a few centimetres over a cube, at most ~2 m over the longest SAR aperture).
    boxes = world.boxes_at(float(t_s[mid]))
    near[near] = line_of_sight(position[mid], static.position_m[near], boxes, static.owner_box[near])
    moving_near[moving_near] = line_of_sight(position[mid], moving_pos[moving_near, mid], boxes, moving.owner_box[moving_near])
    moving_pos = moving_pos[moving_near]
    all_pos = np.concatenate([np.broadcast_to(static.position_m[near][:, None, :], (int(near.sum()), t_s.shape[0], 3)), moving_pos])
    local = unrotate(rotation, all_pos - position[None])
    # Diffuse ground and wall cells return what their view from the radar (middle time) gives.
    static_rcs = static.rcs_m2[near] * view_gains(static.subset(near), position[mid])
    rcs = np.concatenate([static_rcs, moving.rcs_m2[moving_near]])
    swerling1 = np.concatenate([static.swerling1[near], moving.swerling1[moving_near]])
    phase = np.concatenate([static.phase_rad[near], moving.phase_rad[moving_near]])
    if with_velocity:
        return local[:, :m], rcs, swerling1, phase, (local[:, m:] - local[:, :m]) / 1e-4
    return local, rcs, swerling1, phase


def _fluctuation(rng: np.random.Generator, swerling1: np.ndarray, phase: np.ndarray) -> np.ndarray:
    """Per-frame complex factor: Rayleigh amplitude and uniform phase (Swerling 1) or the fixed phase."""
    n = swerling1.shape[0]
    gauss = (rng.standard_normal(n) + 1j * rng.standard_normal(n)) / np.sqrt(2.0)
    return np.where(swerling1, gauss, np.exp(1j * phase))


def _visible(local: np.ndarray, max_range_m: float) -> np.ndarray:
    r = np.linalg.norm(local, axis=-1)
    return (local[..., 0] > 0.0) & (r < max_range_m) & (r > 0.3)


def simulate_cube(truth: SceneTruth, profile: SimProfile, sensor: str, t_center_s: float, rng: np.random.Generator) -> np.ndarray:
    """One range-Doppler cube ``[R, D, A]`` complex64 (signal + thermal noise)."""
    params = ego_model.radar_params(profile)
    front_end = RadarFrontEnd()
    t = t_center_s - params.frame_duration_s / 2 + np.arange(params.n_chirps) * params.chirp_interval_s
    local, rcs, swerling1, phase = _scatterers_in_sensor(truth, sensor, t, params.max_range_m, effects=profile.imperfections)
    mid = local[:, params.n_chirps // 2]
    keep = _visible(mid, params.max_range_m - CUBE_HALF_WIDTH_BINS * params.range_bin_m)
    fluctuation = _fluctuation(rng, swerling1, phase)
    amplitude = front_end.amplitude(params, rcs, mid) * fluctuation
    # Returns far below the noise of one cube cell add nothing visible; skip them.
    noise_w = front_end.noise_power_w(params)
    gain = params.n_samples * params.n_chirps / 4.0
    keep &= np.abs(amplitude) * gain > 0.01 * np.sqrt(noise_w * gain)
    cube = synthesize_cube(params, local[keep], amplitude[keep], half_width_bins=CUBE_HALF_WIDTH_BINS)
    cube *= channel_errors(ego_model.RADARS.index(sensor), params.n_antennas, profile.imperfections).astype(np.complex64)
    noise = thermal_noise(rng, (params.n_chirps, params.n_samples, params.n_antennas), noise_w)
    return cube + range_doppler(noise, workers=1)


def simulate_sar(truth: SceneTruth, profile: SimProfile, sensor: str, t_center_s: float, rng: np.random.Generator,
                 tracklog: PoseInterpolator, device: str | None = None):
    """One SAR image and its ECEF image model: ``(image [H, W], grid_ecef, aperture (t0, t1) s)``.

    ``device``: where the image is backprojected (see :func:`~zendar_dataset.sim.sar_formation.form_image`).
    """
    front_end = RadarFrontEnd()
    mount = ego_model.EGO_T_SENSOR[sensor]
    geometry = sar_footprint(profile, sensor)
    corner_sensor = unrotate(mount.rotation, geometry.corners_ego - mount.translation)
    r_lo, r_hi = 0.0, float(np.linalg.norm(corner_sensor, axis=1).max()) + 3.0
    params = sar_waveform(ego_model.radar_params(profile), profile.sar_bandwidth_hz, r_hi)
    spacing = pulse_spacing_m(params)
    ego = truth.ego
    distance = np.concatenate([[0.0], np.cumsum(0.5 * (ego.speed_mps[1:] + ego.speed_mps[:-1]) * np.diff(ego.time_s))])
    t = aperture_times(ego.time_s, distance, t_center_s, profile.sar_aperture_m, spacing, params.chirp_interval_s)
    local, rcs, swerling1, phase, velocity = _scatterers_in_sensor(
        truth, sensor, t, r_hi, effects=profile.imperfections, with_velocity=True
    )
    mid = local[:, local.shape[1] // 2]
    r_mid = np.linalg.norm(mid, axis=-1)
    keep = _visible(mid, params.max_range_m - SAR_HALF_WIDTH_BINS * params.range_bin_m) & (r_mid > r_lo) & (r_mid < r_hi)
    # Scatterers far outside the imaged square add only cross-range sidelobes to it.
    mid_ego = rotate(mount.rotation, mid) + mount.translation
    half_extent = 0.5 * np.array(geometry.shape) * profile.sar_pixel_m + SAR_MARGIN_M
    keep &= np.all(np.abs(mid_ego[:, :2] - geometry.center_ego[:2]) < half_extent, axis=1)
    fluctuation = _fluctuation(rng, swerling1, phase)[keep]
    local, velocity = local[keep], velocity[keep]
    # Every chirp, presummed to the pulses (sar_formation.chirps_per_pulse): static returns whole,
    # movers outside the static band filtered out, the noise down by the chirps per pulse. A burst of
    # single chirps (the ego did not move) is not presummed.
    chirps = chirps_per_pulse(ego.time_s, distance, t, spacing, params.chirp_interval_s)
    presum = 1.0
    if np.any(chirps > 1.0):
        range_rate = dot(local, velocity) / np.maximum(np.linalg.norm(local, axis=-1), 1e-9)  # [S, P]
        presum = presum_factors(-2.0 * range_rate / params.wavelength_m, t, np.linalg.norm(ego.velocity_at(t), axis=-1),
                                spacing, params.chirp_interval_s)
    # Every receiver, summed coherently: in the far field of the 6 mm array (beyond ~2 cm) their sum
    # focused on a pixel is the signal at the array's centre times the channels' mean gain, with the
    # noise of n_rx independent channels.
    n_rx = params.n_antennas
    gain = channel_errors(ego_model.RADARS.index(sensor), n_rx, profile.imperfections).mean()
    amplitude = front_end.amplitude(params, rcs[keep][:, None], local) * (fluctuation[:, None] * presum * gain)  # [S, P]
    receiver = params.rx_positions_m.mean(axis=0)
    profiles = synthesize_range_profiles(
        params, local.transpose(1, 0, 2), velocity.transpose(1, 0, 2), amplitude.T, receiver, half_width_bins=SAR_HALF_WIDTH_BINS
    )
    noise = thermal_noise(rng, (t.shape[0], params.n_samples, 1), front_end.noise_power_w(params))
    noise *= (1.0 / np.sqrt(chirps * n_rx)).astype(np.float32)[:, None, None]
    profiles = profiles + range_profiles(noise, workers=1)[..., 0]
    # Backprojection uses the written (noisy) tracklog, in the scene's ENU frame.
    ego_r, ego_t = ego_poses_from_tracklog(truth, tracklog, t)
    phase_center_ego = mount.translation + rotate(mount.rotation, receiver / 2.0)
    phase_centers = ego_t + rotate(ego_r, phase_center_ego)
    c_r, c_t = ego_poses_from_tracklog(truth, tracklog, np.array([t_center_s]))
    # Keep the image plane level: only the yaw of the (noisy) ego pose orients it.
    yaw = np.arctan2(c_r[0, 1, 0], c_r[0, 0, 0])
    level = np.array([[np.cos(yaw), -np.sin(yaw), 0.0], [np.sin(yaw), np.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
    grid = geometry.grid_enu(level, c_t[0])
    image = form_image(params, profiles, phase_centers, grid, device)
    return image, grid.transformed(truth.enu.ecef_T_enu), (float(t[0]), float(t[-1]))


def ego_poses_from_tracklog(truth: SceneTruth, tracklog: PoseInterpolator, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ego poses ``enu_T_ego`` at scene times ``t_s`` ``[P]`` as a tracklog gives them (interpolated, through
    the IMU's mount): rotations ``[P, 3, 3]`` and translations ``[P, 3]`` in the scene's ENU frame."""
    stamps = truth.start_ns + np.rint(np.asarray(t_s) * 1e9).astype(np.int64)
    imu_position, imu_attitude = tracklog.at(stamps)
    imu_r = compose(truth.enu.ecef_R_enu.T, quat_wxyz_to_matrix(imu_attitude))  # [P, 3, 3] IMU -> ENU
    ego_from_imu = ego_model.EGO_T_SENSOR[ego_model.IMU]
    ego_r = compose(imu_r, ego_from_imu.rotation.T)
    return ego_r, truth.enu.ecef_to_enu(imu_position) - rotate(ego_r, ego_from_imu.translation)


def sar_footprint(profile: SimProfile, sensor: str) -> SarGeometry:
    """Where ``sensor``'s SAR image lies in the ego frame: its azimuth field of view out to
    ``profile.sar_coverage_m`` and the ego lane ahead to the same distance."""
    mount = ego_model.EGO_T_SENSOR[sensor]
    reach = profile.sar_coverage_m
    lane_ahead = np.array([[0.0, -LANE_WIDTH_M / 2], [0.0, LANE_WIDTH_M / 2], [reach, -LANE_WIDTH_M / 2], [reach, LANE_WIDTH_M / 2]])
    return SarGeometry.covering(
        mount.translation, mount.rotation[:, 0], np.radians(RadarFrontEnd().half_beam_azimuth_deg), reach,
        profile.sar_pixel_m, lane_ahead,
    )


def frame_times(duration_s: float, rate_hz: float) -> np.ndarray:
    """Frame times (scene seconds) at ``rate_hz``, the first half a period in."""
    return (np.arange(int(round(duration_s * rate_hz))) + 0.5) / rate_hz


def free_running_times(duration_s: float, rate_hz: float, jitter_s: float, rng: np.random.Generator) -> np.ndarray:
    """Frame times (scene seconds) of a free-running sensor: a random phase within the first period,
    then ``rate_hz`` with Gaussian jitter of ``jitter_s`` (clipped to a quarter period, so the times
    stay strictly increasing), all inside ``[0, duration_s)``."""
    period = 1.0 / rate_hz
    n = int(round(duration_s * rate_hz))
    jitter = np.clip(rng.normal(0.0, jitter_s, n), -period / 4, period / 4)
    times = rng.uniform(0.0, period) + np.arange(n) * period + jitter
    return times[(times >= 0.0) & (times < duration_s)]


def write_scene(writer, truth: SceneTruth, profile: SimProfile, seed: int, scene_index: int, *, with_labels: bool = True,
                sar_device: str | None = None) -> dict:
    """Simulate every stream of a scene into an open ``SceneWriter``; returns its label rows.

    ``sar_device``: where SAR images are backprojected (``None``: the numba kernel on the CPU).
    """
    duration = profile.scene_duration_s

    def ns(t: float) -> int:
        """Scene seconds to GPS nanoseconds."""
        return truth.start_ns + int(round(float(t) * 1e9))

    clocks = stream_rng(seed, scene_index, "clocks")
    radar_times = {
        sensor: free_running_times(duration, profile.radar_rate_hz, CLOCK_JITTER_S["radar"], clocks)
        for sensor in ego_model.RADARS
    }
    lidar_times = free_running_times(duration, profile.lidar_rate_hz, CLOCK_JITTER_S["lidar"], clocks)
    camera_times = free_running_times(duration, profile.camera_rate_hz, CLOCK_JITTER_S["camera"], clocks)
    written = truth.tracklog_written
    writer.write_tracklog(written.timestamp_ns, written.position_ecef, written.attitude_wxyz)
    tracklog = PoseInterpolator(written.timestamp_ns, written.position_ecef, written.attitude_wxyz)
    for sensor in ego_model.RADARS:
        rng = stream_rng(seed, scene_index, sensor)
        for t in radar_times[sensor]:
            writer.append_radar(sensor, ns(t), simulate_cube(truth, profile, sensor, t, rng))
    sar_times = frame_times(duration, profile.sar_rate_hz)
    for sensor in ego_model.RADARS:
        rng = stream_rng(seed, scene_index, f"sar_{sensor}")
        for t in sar_times:
            image, grid, (t0, t1) = simulate_sar(truth, profile, sensor, t, rng, tracklog, sar_device)
            writer.append_sar(sensor, ns(t), image, grid.origin, grid.di, grid.dj, np.array([ns(t0), ns(t1)], np.int64),
                              ego_stopped=ego_model.stood_still(truth.ego, t0, t1))
    rng = stream_rng(seed, scene_index, "lidar")
    returns_per_sweep = {}
    for t in lidar_times:
        rotation, position = ego_model.sensor_poses_enu(truth.ego, ego_model.LIDAR, np.array(t))
        boxes = truth.world.boxes_at(t)
        points, hit = lidar_sweep(rng, rotation, position, boxes, profile.lidar_azimuth_step_deg)
        writer.append_lidar(ego_model.LIDAR, ns(t), points)
        tracks = boxes.track_id[hit[hit >= 0]]
        returns_per_sweep[float(t)] = np.bincount(tracks[tracks > 0], minlength=len(truth.world.cars) + 1)
    k, distortion = ego_model.camera_intrinsics(profile)
    rays = camera_model.pixel_rays(k, distortion, *profile.camera_shape)
    for t in camera_times:
        rotation, position = ego_model.sensor_poses_enu(truth.ego, ego_model.CAMERA, np.array(t))
        writer.append_camera(ego_model.CAMERA, ns(t), camera_model.render(rays, rotation, position, truth.world.boxes_at(t)))
    views = radar_views(ego_model.radar_params(profile).max_range_m)
    labels = label_rows(truth.world, truth.ego, sar_times, returns_per_sweep, [ns(t) for t in sar_times], views)
    if with_labels:
        writer.write_labels(labels)
    return labels
