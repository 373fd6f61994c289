"""Simulation profiles: the numbers that size a synthetic dataset.

``paper`` follows the paper (512 x 256 x 4 cubes with 18 cm range bins; SAR
from a 3.75 GHz waveform (4 cm range resolution, paper section 1.1.1) over 2 m
apertures, imaged at 4 cm pixels out to 60 m across each radar's field of view;
a 24 Hz camera; scenes of tens of seconds). ``demo`` is what the main command runs on a 2-core laptop and
``tiny`` is what the tests run; their reductions are listed in
docs/simulator.md and in each profile's ``reductions``. ``demo-short`` is ``demo`` cut into many 1 s
scenes with dense traffic, for the benchmark: what tells two detectors apart is how many *different*
cars each range band holds, and a short scene with many cars adds more of them per simulated second
than a long one (a car stays in view for seconds).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import asdict, dataclass, field, replace

from zendar_dataset.errors import ZendarError
from zendar_dataset.radar.fmcw import SPEED_OF_LIGHT_MPS
from zendar_dataset.sim.imperfections import Imperfections


# Five frames of the 10 Hz streams: shorter scenes can leave a free-running stream empty.
MIN_SCENE_DURATION_S = 0.5


@dataclass(frozen=True)
class SimProfile:
    """Everything that sizes one synthetic scene.

    Attributes
    ----------
    name : str
        ``"tiny"``, ``"demo"``, ``"demo-short"`` or ``"paper"``.
    scene_duration_s : float
        Length of each scene (all streams), seconds.
    default_scenes : int
        Scenes written when the caller does not say.
    n_range_bins, n_doppler_bins, n_rx : int
        Radar cube shape ``[R, D, A]``; ``R`` is also the number of fast-time samples.
    range_bin_m : float
        Range bin spacing ``c / (2 B)``, metres.
    max_velocity_mps : float
        Unambiguous radial speed ``lambda / (4 T_c)``; sets the chirp interval.
    radar_rate_hz : float
        Cubes per second per radar.
    sar_pixel_m, sar_aperture_m, sar_rate_hz
        SAR pixel size (m), synthetic aperture length (m), images per second.
    sar_bandwidth_hz : float
        Swept bandwidth of the waveform the SAR images are formed from (Hz); its range
        resolution ``c / (2 B)`` is matched to ``sar_pixel_m``. The cubes keep ``bandwidth_hz``.
    sar_coverage_m : float
        Each radar's SAR image covers its azimuth field of view out to this range (m).
    lidar_azimuth_step_deg : float
        Horizontal angle between lidar firings (VLP-16: 0.2 deg at 10 Hz).
    camera_shape : tuple of int
        Camera image ``(H, W)``; ``camera_rate_hz`` its frame rate.
    n_moving_cars : tuple of int
        Inclusive range of the number of moving cars per scene.
    facade_spacing_m : float
        Spacing of the point scatterers along building facades.
    reductions : tuple of str
        How the profile departs from the paper.
    imperfections : Imperfections
        Clutter, multipath, car aspect, wheel micro-Doppler and antenna errors (all on by default).
    """

    name: str
    scene_duration_s: float
    default_scenes: int
    n_range_bins: int
    n_doppler_bins: int
    n_rx: int
    range_bin_m: float
    max_velocity_mps: float
    radar_rate_hz: float
    sar_pixel_m: float
    sar_bandwidth_hz: float
    sar_coverage_m: float
    sar_aperture_m: float
    sar_rate_hz: float
    lidar_rate_hz: float
    lidar_azimuth_step_deg: float
    camera_rate_hz: float
    camera_shape: tuple[int, int]
    n_moving_cars: tuple[int, int]
    facade_spacing_m: float
    reductions: tuple[str, ...] = field(default=())
    imperfections: Imperfections = field(default=Imperfections())

    def __post_init__(self) -> None:
        problems = []
        for key in ("scene_duration_s", "range_bin_m", "max_velocity_mps", "radar_rate_hz", "sar_pixel_m",
                    "sar_bandwidth_hz", "sar_coverage_m", "sar_aperture_m", "sar_rate_hz", "lidar_rate_hz",
                    "lidar_azimuth_step_deg", "camera_rate_hz", "facade_spacing_m"):
            value = getattr(self, key)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                problems.append(f"{key} must be a positive number, got {value!r}")
        for key in ("default_scenes", "n_range_bins", "n_doppler_bins", "n_rx"):
            value = getattr(self, key)
            if not (isinstance(value, int) and value >= 1):
                problems.append(f"{key} must be a positive integer, got {value!r}")
        low, high = self.n_moving_cars
        if not 0 <= low <= high:
            problems.append(f"n_moving_cars must be (low, high) with 0 <= low <= high, got {self.n_moving_cars}")
        if problems:
            raise ZendarError(f"invalid simulation profile {self.name!r}: " + "; ".join(problems))

    @property
    def center_frequency_hz(self) -> float:
        return 77.0e9

    @property
    def bandwidth_hz(self) -> float:
        """Swept bandwidth that gives ``range_bin_m``, ``c / (2 * range_bin_m)``."""
        return SPEED_OF_LIGHT_MPS / (2.0 * self.range_bin_m)

    @property
    def chirp_interval_s(self) -> float:
        """``T_c = lambda / (4 v_max)``."""
        return SPEED_OF_LIGHT_MPS / self.center_frequency_hz / (4.0 * self.max_velocity_mps)

    @property
    def sample_rate_hz(self) -> float:
        """Fast-time rate that fills 85 % of the chirp interval with the ADC window."""
        return self.n_range_bins / (0.85 * self.chirp_interval_s)

    def with_duration(self, scene_duration_s: float) -> SimProfile:
        """This profile with scenes of ``scene_duration_s`` seconds, the change listed in ``reductions``.

        Raises
        ------
        ZendarError
            When ``scene_duration_s`` is not a finite number of at least ``MIN_SCENE_DURATION_S``, or
            not a whole number of SAR frame periods.
        """
        if not (isinstance(scene_duration_s, numbers.Real) and not isinstance(scene_duration_s, bool)
                and math.isfinite(scene_duration_s) and scene_duration_s >= MIN_SCENE_DURATION_S):
            raise ZendarError(
                f"scene duration must be a number of seconds >= {MIN_SCENE_DURATION_S:g}, got {scene_duration_s!r}"
            )
        scene_duration_s = float(scene_duration_s)
        # SAR (and label) frames sit half a period into each period: a partial last period would put
        # one at the scene's very end, after every free-running stream has stopped.
        periods = scene_duration_s * self.sar_rate_hz
        if abs(periods - round(periods)) > 1e-6:
            raise ZendarError(
                f"scene duration must be a whole number of SAR frame periods ({1 / self.sar_rate_hz:g} s), "
                f"got {scene_duration_s:g}"
            )
        if scene_duration_s == self.scene_duration_s:
            return self
        note = f"{scene_duration_s:g} s scenes instead of the profile's {self.scene_duration_s:g} s"
        return replace(self, scene_duration_s=scene_duration_s, reductions=(*self.reductions, note))

    def to_json(self) -> dict:
        """Plain-JSON description (recorded in dataset.json for resumable runs)."""
        out = asdict(self)
        out["camera_shape"] = list(self.camera_shape)
        out["n_moving_cars"] = list(self.n_moving_cars)
        out["reductions"] = list(self.reductions)
        return out


PROFILES: dict[str, SimProfile] = {
    "paper": SimProfile(
        name="paper",
        scene_duration_s=30.0,
        default_scenes=27,
        n_range_bins=512,
        n_doppler_bins=256,
        n_rx=4,
        range_bin_m=0.18,
        max_velocity_mps=20.0,
        radar_rate_hz=10.0,
        sar_pixel_m=0.04,
        sar_bandwidth_hz=3.75e9,
        sar_coverage_m=60.0,
        sar_aperture_m=2.0,
        sar_rate_hz=10.0,
        lidar_rate_hz=10.0,
        lidar_azimuth_step_deg=0.2,
        camera_rate_hz=24.0,
        camera_shape=(480, 640),
        n_moving_cars=(5, 15),
        facade_spacing_m=0.15,
    ),
    "demo": SimProfile(
        name="demo",
        scene_duration_s=6.0,
        default_scenes=5,
        n_range_bins=256,
        n_doppler_bins=64,
        n_rx=4,
        range_bin_m=0.36,
        max_velocity_mps=20.0,
        radar_rate_hz=10.0,
        sar_pixel_m=0.16,
        sar_bandwidth_hz=SPEED_OF_LIGHT_MPS / (2 * 0.16),
        sar_coverage_m=60.0,
        sar_aperture_m=0.25,
        sar_rate_hz=10.0,
        lidar_rate_hz=10.0,
        lidar_azimuth_step_deg=0.4,
        camera_rate_hz=12.0,
        camera_shape=(180, 320),
        n_moving_cars=(5, 10),
        facade_spacing_m=0.4,
        reductions=(
            "256 range bins of 0.36 m (same 92 m reach) instead of 512 of 0.18 m",
            "64 Doppler bins instead of 256",
            "SAR pixels of 16 cm from a 0.94 GHz waveform and 0.25 m apertures (resolution matched to the pixel)",
            "lidar firing every 0.4 deg instead of 0.2 deg",
            "camera 320 x 180 at 12 Hz",
            "6 s scenes, 5 to 10 moving cars",
        ),
    ),
    "tiny": SimProfile(
        name="tiny",
        scene_duration_s=1.0,
        default_scenes=3,
        n_range_bins=64,
        n_doppler_bins=32,
        n_rx=4,
        range_bin_m=0.6,
        max_velocity_mps=20.0,
        radar_rate_hz=10.0,
        sar_pixel_m=0.4,
        sar_bandwidth_hz=SPEED_OF_LIGHT_MPS / (2 * 0.4),
        sar_coverage_m=60.0,
        sar_aperture_m=0.1,
        sar_rate_hz=10.0,
        lidar_rate_hz=10.0,
        lidar_azimuth_step_deg=2.0,
        camera_rate_hz=12.0,
        camera_shape=(48, 64),
        n_moving_cars=(3, 5),
        facade_spacing_m=1.0,
        reductions=(
            "64 x 32 x 4 cubes with 0.6 m range bins",
            "SAR pixels of 40 cm from a 0.37 GHz waveform and 0.1 m apertures",
            "lidar firing every 2 deg, camera 64 x 48 at 12 Hz",
            "1 s scenes, 3 to 5 moving cars",
        ),
    ),
}

# demo's sensors; 1 s scenes and twice demo's cars at most. The street holds about 18 of them on
# average (a car that would touch another body is drawn again, then left out: traffic.MAX_DRAWS).
PROFILES["demo-short"] = replace(
    PROFILES["demo"], name="demo-short", scene_duration_s=1.0, default_scenes=60, n_moving_cars=(20, 30),
    reductions=(*PROFILES["demo"].reductions[:-1], "1 s scenes, 20 to 30 moving cars (about 18 fit the street)"),
)


def get_profile(name: str | SimProfile) -> SimProfile:
    """The profile called ``name`` (a :class:`SimProfile` is returned as is).

    Raises
    ------
    ZendarError
        For an unknown name, listing the known ones.
    """
    if isinstance(name, SimProfile):
        return name
    try:
        return PROFILES[name]
    except KeyError:
        raise ZendarError(f"unknown simulation profile {name!r}; choose one of {sorted(PROFILES)}") from None
