"""What the importer assumes about the release, and the words the summary says it in.

The release states neither its sensors' extrinsics, nor which radar serial is
which side (decided and checked in ``release/sides.py``), nor (without a ``RangeDopplerImageModel``) the radar numbers format v1
requires; its axis conventions differ from format v1's.  Each constant and
decision the importer takes in their place lives here, with the sentence it
records in the import summary and in the scene's root attribute
``release_import`` (docs/release.md, "What is assumed").  Functions that decide
append their sentences to ``assumed``; the others return the sentence.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from zendar_dataset.geometry import ecef_to_geodetic
from zendar_dataset.release import records as rec

SPEED_OF_LIGHT_MPS = 299_792_458.0
# Radar numbers used only when a radar has no RangeDopplerImageModel (format v1 requires them).
PAPER_CENTER_FREQUENCY_HZ = 77e9
PAPER_RANGE_BIN_M = 0.176
PLACEHOLDER_DOPPLER_BIN_MPS = 0.1
PAPER_CUBE_SHAPE = (512, 256, 4)  # paper §3.1: range bins, Doppler bins, receive channels
# IMU frame (forward, right, down) -> ego frame (forward, left, up): 180 degrees about x.
EGO_Q_IMU_WXYZ = (0.0, 1.0, 0.0, 0.0)
# A radar looking to the ego's left (+y) or right (-y): its boresight x turned by +-90 degrees about z.
SIDE_Q_WXYZ = {"left": (np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)), "right": (np.sqrt(0.5), 0.0, 0.0, -np.sqrt(0.5))}

TRACKLOG_ATTITUDE = "Position.attitude rotates IMU (forward, right, down) vectors into ECEF; quaternions normalised"


def imu_entry(assumed: list[str]) -> dict:
    """The IMU's calibration entry: at the ego origin, forward-right-down axes (the paper's)."""
    entry = {"rotation_wxyz": list(EGO_Q_IMU_WXYZ), "translation_m": [0.0, 0.0, 0.0]}
    assumed.append("IMU at the ego origin, axes forward-right-down (ego_T_imu: 180 degrees about x)")
    return entry


def sensor_entry(name: str, assumed: list[str]) -> dict:
    """A lidar's or camera's calibration entry: the identity pose (the release ships no extrinsics)."""
    entry = {"rotation_wxyz": [1.0, 0.0, 0.0, 0.0], "translation_m": [0.0, 0.0, 0.0]}
    assumed.append(f"sensor {name!r} pose in the ego frame: identity (no extrinsics in the release)")
    return entry


def enu_origin(tracklog_position_ecef: np.ndarray | None, sar_frames: Iterable[rec.SarFrame], assumed: list[str]) -> dict:
    """The scene's ENU origin: the first tracklog position, else the first geolocated SAR image origin, else (0, 0, 0).

    ``sar_frames`` is read only when there is no tracklog, and only up to the first usable frame.
    """
    anchor = None
    if tracklog_position_ecef is not None:
        anchor, what = tracklog_position_ecef, "the first tracklog position"
    else:
        for frame in sar_frames:
            if np.all(np.isfinite(frame.origin_ecef)):
                anchor, what = frame.origin_ecef, "the first SAR image origin"
                break
    if anchor is None:
        assumed.append("enu_origin: nothing geolocated in the scene; (0, 0, 0) used")
        return {"lat_deg": 0.0, "lon_deg": 0.0, "height_m": 0.0}
    lat, lon, height = (float(np.asarray(v).reshape(-1)[0]) for v in ecef_to_geodetic(np.asarray(anchor).reshape(1, 3)))
    assumed.append(f"enu_origin: {what}")
    return {"lat_deg": lat, "lon_deg": lon, "height_m": height}


def paper_model() -> rec.RangeDopplerModel:
    """The paper's cube layout for frames that come without a model: 512 × 0.176 m range bins, 256 Doppler
    bins centred on zero (bin size a placeholder) and 4 receivers half a wavelength apart along the
    release radar frame's x (left) axis (placeholder positions)."""
    r, d, a = PAPER_CUBE_SHAPE
    wavelength = SPEED_OF_LIGHT_MPS / PAPER_CENTER_FREQUENCY_HZ
    rx = np.column_stack([np.arange(a) * wavelength / 2, np.zeros(a), np.zeros(a)])
    return rec.RangeDopplerModel(
        a, (0.0, PAPER_RANGE_BIN_M, r), (-(d // 2) * PLACEHOLDER_DOPPLER_BIN_MPS, PLACEHOLDER_DOPPLER_BIN_MPS, d), rx, wavelength
    )


def radar_entry(name: str, model: rec.RangeDopplerModel | None, assumed: list[str], assumed_model: bool = False) -> dict:
    """A radar's calibration entry: its pose from its side, its numbers from ``model`` or placeholders.

    Parameters
    ----------
    name
        The radar's name; ``"left"`` and ``"right"`` place it looking to that side.
    model
        Its range-Doppler model, or None (placeholder numbers).
    assumed
        Where the assumptions are recorded.
    assumed_model
        ``model`` is :func:`paper_model`, taken from the size of the radar's frames.
    """
    side = name if name in SIDE_Q_WXYZ else None
    rotation = list(SIDE_Q_WXYZ[side]) if side else [1.0, 0.0, 0.0, 0.0]
    assumed.append(
        f"radar {name!r} pose in the ego frame: "
        + (f"looking to the {side} (boresight along ego {'+' if side == 'left' else '-'}y)" if side else "identity")
        + " at the ego origin; the release ships no extrinsics the importer could read"
    )
    if model is None:
        assumed.append(
            f"radar {name!r}: no RangeDopplerImageModel, so calibration numbers are placeholders format v1 requires: "
            f"{PAPER_CENTER_FREQUENCY_HZ / 1e9:g} GHz and {PAPER_RANGE_BIN_M} m range bins (paper), "
            f"{PLACEHOLDER_DOPPLER_BIN_MPS} m/s Doppler bins and one antenna at the origin (unknown)"
        )
        range_bin = PAPER_RANGE_BIN_M
        return {
            "rotation_wxyz": rotation,
            "translation_m": [0.0, 0.0, 0.0],
            "center_frequency_hz": PAPER_CENTER_FREQUENCY_HZ,
            "bandwidth_hz": SPEED_OF_LIGHT_MPS / (2 * range_bin),
            "range_bin_m": range_bin,
            "doppler_bin_mps": PLACEHOLDER_DOPPLER_BIN_MPS,
            "rx_positions_m": [[0.0, 0.0, 0.0]],
        }
    # The release's radar frame is x left, y up, z forward; format v1's is x forward, y left, z up.
    rx = model.rx_positions_m[:, [2, 0, 1]] if model.rx_positions_m.size else np.zeros((model.num_rx, 3))
    if assumed_model:
        assumed.append(
            f"radar {name!r}: no RangeDopplerImageModel; its frames are 8 x 512 x 256 x 4 bytes, so the paper's "
            f"cube layout is assumed: 512 range bins of {PAPER_RANGE_BIN_M} m, 256 Doppler bins centred on zero, "
            f"4 receivers at {PAPER_CENTER_FREQUENCY_HZ / 1e9:g} GHz; the Doppler bin ({PLACEHOLDER_DOPPLER_BIN_MPS} m/s) "
            f"and the receiver positions (half-wavelength line) are placeholders"
        )
    else:
        assumed.append(
            f"radar {name!r}: receiver positions taken in the release's radar frame (x left, y up, z forward) and "
            f"reordered to format v1's (x boresight, y left, z up); bandwidth = c / (2 * range bin)"
        )
    return {
        "rotation_wxyz": rotation,
        "translation_m": [0.0, 0.0, 0.0],
        "center_frequency_hz": SPEED_OF_LIGHT_MPS / model.wavelength_m,
        "bandwidth_hz": SPEED_OF_LIGHT_MPS / (2 * model.range_axis[1]),
        "range_bin_m": model.range_axis[1],
        "doppler_bin_mps": abs(model.doppler_axis[1]),
        "rx_positions_m": rx.tolist(),
    }


def shared_model(path: str, name: str) -> str:
    """A scene's only range-Doppler model, taken for radar ``name`` whose file names none."""
    return f"range-Doppler model {path} applies to {name!r} (the only model in the scene)"


def doppler_shift(model: rec.RangeDopplerModel) -> tuple[str | None, str]:
    """How to bring the Doppler axis to format v1's (zero velocity at bin D/2): ``"none"``, ``"fftshift"`` or None."""
    start, delta, count = model.doppler_axis
    r_start, r_delta, _ = model.range_axis
    if not (r_delta > 0 and abs(r_start) <= 1e-6 * r_delta):
        return None, f"range axis starts at {r_start} m with {r_delta} m bins; format v1 needs bin 0 at 0 m"
    if not delta > 0:
        return None, f"Doppler axis step {delta} is not positive"
    if abs(start + (count // 2) * delta) <= 1e-6 * delta:
        return "none", "Doppler axis centred (zero velocity at bin D/2), as format v1"
    if abs(start) <= 1e-6 * delta:
        return "fftshift", "Doppler axis starts at 0 m/s: taken as FFT order and fftshifted to put zero at bin D/2"
    return None, f"Doppler axis starts at {start} m/s with {delta} m/s bins, neither centred nor FFT order"


def cube_axes(name: str, why: str) -> list[str]:
    """A radar's cubes: their Doppler axis (``why`` from :func:`doppler_shift`) and velocity sign."""
    return [f"radar/{name}: {why}", f"radar/{name}: range velocity sign as recorded (unknown convention)"]


def pixel_order(name: str, i_fastest: bool | None, evidence: str, assumed: list[str]) -> bool:
    """Whether SAR pixel (i, j) is flat element ``j*rows + i``: the vote's answer, else the SDK viewer's reading.

    ``i_fastest`` and ``evidence`` are :func:`zendar_dataset.release.pixel_order.vote_pixel_order`'s.
    """
    if i_fastest is None:
        assumed.append(
            f"sar/{name}: pixel (i, j) is flat element j*rows + i (the SDK viewer's reading; not verifiable here: {evidence})"
        )
        return True
    order = "j*rows + i (the SDK viewer's reading)" if i_fastest else "i*cols + j (row-major, NOT the SDK viewer's reading)"
    assumed.append(f"sar/{name}: pixel (i, j) is flat element {order}: checked, {evidence}")
    return i_fastest


def sar_pixels_and_aperture(name: str, magnitude_only: bool) -> list[str]:
    """A radar's SAR images: how their pixels were read, and the aperture the release does not give."""
    return [
        f"sar/{name}: "
        + ("magnitude-only (4-byte pixels, read as little-endian uint32)" if magnitude_only else "complex64 pixels"),
        f"sar/{name}: aperture start/end are not in the release; aperture_ns = [t, t]",
    ]


def detection_fields(name: str, generation: str) -> str:
    """What detection fields 3 and 10 (stored as ``magnitude`` and ``snr``) mean in ``generation``."""
    meaning = "amplitude / confidence" if generation == "2020" else "magnitude / doa_snr"
    return f"detections/{name}: magnitude and snr are the release's {meaning} (fields 3, 10)"


def lidar_frame(name: str, points_in_enu: bool) -> str:
    """The frame a lidar's points are written in: the scene's ENU frame, or the release's local positions."""
    if points_in_enu:
        return f"lidar/{name}: the release gives no local positions (or ECEF ones), so points are in the scene's ENU frame"
    return f"lidar/{name}: LidarPoint.position_local taken as the lidar frame (unknown in the release)"


def camera_video(name: str) -> str:
    """A camera's video is not converted, only its index."""
    return f"camera_index/{name}: the video itself is not converted (container unknown)"
