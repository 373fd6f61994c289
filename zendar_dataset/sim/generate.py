"""Synthesise a whole format-v1 dataset: scenes, splits, ``dataset.json``.

Resumable: the settings are recorded in ``OUT/simulation.json`` before any
scene is written; scenes are written through the atomic ``SceneWriter``, so a
scene store at its final path is complete.  Re-running with the same settings
skips the complete scenes; a directory holding anything else is refused, never
overwritten.
"""

from __future__ import annotations

import json
import os
import pathlib
import shutil

from tqdm import tqdm

from zendar_dataset.errors import ZendarError
from zendar_dataset.format.schema import BACKEND_SUFFIX, DATASET_JSON, frame_id
from zendar_dataset.format.writer import DatasetWriter, write_json_atomic
from zendar_dataset.sim import ego as ego_model
from zendar_dataset.sim.profiles import SimProfile, get_profile
from zendar_dataset.sim.scene import build_scene, write_scene

SIDECAR = "simulation.json"
GROUND_TRUTH_DIR = "ground_truth"
TEST_GROUND_TRUTH = "test_ground_truth.json"


def split_scene_ids(n_scenes: int, split_ratios: tuple[float, float, float]) -> dict[str, list[str]]:
    """Scene ids ``scene-0000``... assigned in order to train, val and test by ``split_ratios``."""
    ratios = [float(r) for r in split_ratios]
    if len(ratios) != 3 or any(r < 0 for r in ratios) or sum(ratios) <= 0:
        raise ZendarError(f"split ratios must be three non-negative numbers (train, val, test), got {split_ratios!r}")
    total = sum(ratios)
    n_val = int(round(n_scenes * ratios[1] / total))
    n_test = min(n_scenes - n_val, int(round(n_scenes * ratios[2] / total)))
    n_train = n_scenes - n_val - n_test
    ids = [f"scene-{i:04d}" for i in range(n_scenes)]
    return {"train": ids[:n_train], "val": ids[n_train : n_train + n_val], "test": ids[n_train + n_val :]}


def _settings(profile: SimProfile, n_scenes: int, seed: int, split_ratios, backend: str, withhold: bool) -> dict:
    return {
        "generator": "zendar_dataset.sim",
        "profile": profile.to_json(),
        "scenes": int(n_scenes),
        "seed": int(seed),
        "split_ratios": [float(r) for r in split_ratios],
        "backend": backend,
        "withhold_test_labels": bool(withhold),
    }


def _prepare_output(out: pathlib.Path, settings: dict) -> None:
    sidecar = out / SIDECAR
    if sidecar.exists():
        try:
            recorded = json.loads(sidecar.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as exc:
            raise ZendarError(f"{sidecar}: unreadable simulation record ({exc}); not touching {out}") from None
        if recorded != settings:
            differing = sorted(k for k in set(recorded) | set(settings) if recorded.get(k) != settings.get(k))
            raise ZendarError(
                f"{out} holds a dataset simulated with other settings (differing: {', '.join(differing)}); "
                "re-run with the recorded settings to resume, or choose another directory"
            )
        return
    if out.exists() and any(out.iterdir()):
        raise ZendarError(f"{out} is not empty and holds no {SIDECAR}: refusing to write a dataset into it")
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(sidecar, settings)


def _remove_interrupted(out: pathlib.Path) -> None:
    """Delete temporary scene stores left by an interrupted run (hidden ``.<scene>.tmp-*`` entries)."""
    scenes = out / "scenes"
    if not scenes.is_dir():
        return
    for entry in scenes.iterdir():
        if entry.name.startswith(".scene-") and ".tmp-" in entry.name:
            shutil.rmtree(entry, ignore_errors=True) if entry.is_dir() else entry.unlink()


def synthesize_dataset(
    out: str | os.PathLike,
    profile: str | SimProfile = "demo",
    n_scenes: int | None = None,
    seed: int = 0,
    split_ratios: tuple[float, float, float] = (0.6, 0.2, 0.2),
    backend: str = "zarr",
    progress: bool = True,
    withhold_test_labels: bool = False,
) -> pathlib.Path:
    """Write a synthetic dataset to ``out`` (or finish an interrupted one).

    Parameters
    ----------
    out : path-like
        Dataset root; must be new, empty, or a previous run with the same settings.
    profile : {"tiny", "demo", "paper"} or SimProfile
    n_scenes : int, optional
        Default: the profile's ``default_scenes``.
    seed : int
        Same seed and profile give byte-identical arrays.
    split_ratios : (train, val, test)
    backend : {"zarr", "hdf5"}
    progress : bool
        Show a tqdm progress bar over scenes.
    withhold_test_labels : bool
        Write test scenes without ``labels/moving_cars`` and put their ground
        truth in ``OUT/test_ground_truth.json`` (the ``export-gt`` layout).

    Returns
    -------
    pathlib.Path
        ``out``.

    Raises
    ------
    ZendarError
        When ``out`` holds something else, or an argument is invalid.
    """
    profile = get_profile(profile)
    n_scenes = profile.default_scenes if n_scenes is None else int(n_scenes)
    if n_scenes < 1:
        raise ZendarError(f"the number of scenes must be at least 1, got {n_scenes}")
    if backend not in BACKEND_SUFFIX:
        raise ZendarError(f"backend must be one of {sorted(BACKEND_SUFFIX)}, got {backend!r}")
    splits = split_scene_ids(n_scenes, split_ratios)
    out = pathlib.Path(out)
    _prepare_output(out, _settings(profile, n_scenes, seed, split_ratios, backend, withhold_test_labels))
    _remove_interrupted(out)
    writer = DatasetWriter(out, f"zendar-sim-{profile.name}", backend=backend, overwrite=True)
    calibration = ego_model.calibration(profile)
    test_ids = set(splits["test"])
    scene_ids = [f"scene-{i:04d}" for i in range(n_scenes)]
    for index, scene_id in enumerate(tqdm(scene_ids, desc=f"synth {profile.name}", unit="scene", disable=not progress)):
        gt_path = out / GROUND_TRUTH_DIR / f"{scene_id}.json"
        withhold = withhold_test_labels and scene_id in test_ids
        if writer.scene_path(scene_id).exists() and (not withhold or gt_path.exists()):
            continue
        truth = build_scene(profile, seed, index)
        origin = {"lat_deg": truth.enu.lat_deg, "lon_deg": truth.enu.lon_deg, "height_m": truth.enu.height_m}
        with writer.scene(scene_id, enu_origin=origin, calibration=calibration, overwrite=False) as scene:
            labels = write_scene(scene, truth, profile, seed, index, with_labels=not withhold)
        if withhold:
            gt_path.parent.mkdir(exist_ok=True)
            write_json_atomic(gt_path, _frames(scene_id, labels, truth, profile))
    writer.finalize(splits)
    if withhold_test_labels:
        frames: dict = {}
        for scene_id in splits["test"]:
            frames.update(json.loads((out / GROUND_TRUTH_DIR / f"{scene_id}.json").read_text(encoding="utf-8")))
        write_json_atomic(out / TEST_GROUND_TRUTH, {"frames": frames})
    return out


def _frames(scene_id: str, labels: dict, truth, profile: SimProfile) -> dict:
    """Ground truth of one scene in the ``export-gt`` layout (every SAR frame, empty lists included)."""
    from zendar_dataset.sim.scene import frame_times

    stamps = [truth.start_ns + int(round(float(t) * 1e9)) for t in frame_times(profile.scene_duration_s, profile.sar_rate_hz)]
    frames: dict[str, list] = {frame_id(scene_id, s): [] for s in stamps}
    for row in range(labels["timestamp_ns"].shape[0]):
        car = {k: float(labels[k][row]) for k in ("x", "y", "length", "width", "yaw", "vx", "vy")}
        car["track_id"] = int(labels["track_id"][row])
        frames[frame_id(scene_id, int(labels["timestamp_ns"][row]))].append(car)
    return frames


__all__ = ["DATASET_JSON", "synthesize_dataset", "split_scene_ids"]
