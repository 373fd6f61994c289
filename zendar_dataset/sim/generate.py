"""Synthesise a whole format-v1 dataset: scenes, splits, ``dataset.json``.

Resumable: the settings are recorded in ``OUT/simulation.json`` before any
scene is written; scenes are written through the atomic ``SceneWriter``, so a
scene store at its final path is complete.  Re-running with the same settings
skips the complete scenes; a directory holding anything else is refused, never
overwritten.

Parallel: scenes are independent (each seeds its own random streams and is
published by its own atomic rename), so ``jobs`` worker processes write one
scene each at a time and the bytes do not depend on ``jobs``.  Workers are
started with ``spawn``: numba's GNU OpenMP thread pool is not fork-safe.
"""

from __future__ import annotations

import itertools
import json
import multiprocessing
import os
import pathlib
import queue
import shutil
import signal
from dataclasses import dataclass

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


class SceneSynthesisError(RuntimeError):
    """Simulating or writing one scene failed; ``scene_id`` names it and the message carries the cause."""

    def __init__(self, scene_id: str, message: str) -> None:
        super().__init__(f"{scene_id}: {message}")
        self.scene_id = scene_id
        self.cause_message = message

    def __reduce__(self):
        # Rebuilt from both arguments when it crosses from a worker process.
        return (type(self), (self.scene_id, self.cause_message))


def usable_cpus() -> int:
    """CPUs this process may run on (its affinity mask, not the machine's count)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # no affinity API (macOS, Windows)
        return os.cpu_count() or 1


def synthesize_dataset(
    out: str | os.PathLike,
    profile: str | SimProfile = "demo",
    n_scenes: int | None = None,
    seed: int = 0,
    split_ratios: tuple[float, float, float] = (0.6, 0.2, 0.2),
    backend: str = "zarr",
    progress: bool = True,
    withhold_test_labels: bool = False,
    jobs: int | None = None,
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
        Same seed and profile give byte-identical arrays, whatever ``jobs``.
    split_ratios : (train, val, test)
    backend : {"zarr", "hdf5"}
    progress : bool
        Show a tqdm progress bar over scenes (it advances as each scene is finished).
    withhold_test_labels : bool
        Write test scenes without ``labels/moving_cars`` and put their ground
        truth in ``OUT/test_ground_truth.json`` (the ``export-gt`` layout).
    jobs : int, optional
        Worker processes, each writing one scene at a time. Default: the usable
        CPUs (:func:`usable_cpus`); never more than the scenes left to write.
        ``1`` simulates in this process. Each worker's numba and BLAS threads
        are capped so that ``jobs * threads`` does not exceed the usable CPUs.

    Returns
    -------
    pathlib.Path
        ``out``.

    Raises
    ------
    ZendarError
        When ``out`` holds something else, or an argument is invalid.
    SceneSynthesisError
        When simulating a scene fails (the message names the scene and the cause).
        No scene is started after it; the ones finished (also those in progress
        in other workers) are kept and a re-run resumes.
    """
    profile = get_profile(profile)
    n_scenes = profile.default_scenes if n_scenes is None else int(n_scenes)
    if n_scenes < 1:
        raise ZendarError(f"the number of scenes must be at least 1, got {n_scenes}")
    if backend not in BACKEND_SUFFIX:
        raise ZendarError(f"backend must be one of {sorted(BACKEND_SUFFIX)}, got {backend!r}")
    if jobs is not None and (not isinstance(jobs, int) or jobs < 1):
        raise ZendarError(f"jobs must be a positive integer, got {jobs!r}")
    splits = split_scene_ids(n_scenes, split_ratios)
    out = pathlib.Path(out)
    _prepare_output(out, _settings(profile, n_scenes, seed, split_ratios, backend, withhold_test_labels))
    _remove_interrupted(out)
    writer = DatasetWriter(out, f"zendar-sim-{profile.name}", backend=backend, overwrite=True)
    test_ids = set(splits["test"])
    todo = []
    for index in range(n_scenes):
        task = _SceneTask(out, profile, seed, backend, index, withhold_test_labels and f"scene-{index:04d}" in test_ids)
        if not task.is_complete(writer):
            todo.append(task)
    bar = tqdm(total=n_scenes, initial=n_scenes - len(todo), desc=f"synth {profile.name}", unit="scene", disable=not progress)
    with bar:
        cpus = usable_cpus()
        n_jobs = min(cpus if jobs is None else jobs, len(todo))
        if n_jobs <= 1:
            for task in todo:
                _run_task(task)
                bar.update()
        else:
            _run_in_workers(out, todo, n_jobs, max(1, cpus // n_jobs), bar)
    writer.finalize(splits)
    if withhold_test_labels:
        frames: dict = {}
        for scene_id in splits["test"]:
            frames.update(json.loads((out / GROUND_TRUTH_DIR / f"{scene_id}.json").read_text(encoding="utf-8")))
        write_json_atomic(out / TEST_GROUND_TRUTH, {"frames": frames})
    return out


@dataclass(frozen=True)
class _SceneTask:
    """One scene to simulate and write (picklable, sent to a worker process)."""

    out: pathlib.Path
    profile: SimProfile
    seed: int
    backend: str
    index: int
    withhold: bool

    @property
    def scene_id(self) -> str:
        return f"scene-{self.index:04d}"

    @property
    def gt_path(self) -> pathlib.Path:
        return self.out / GROUND_TRUTH_DIR / f"{self.scene_id}.json"

    def is_complete(self, writer: DatasetWriter) -> bool:
        return writer.scene_path(self.scene_id).exists() and (not self.withhold or self.gt_path.exists())

    def run(self) -> None:
        profile = self.profile
        writer = DatasetWriter(self.out, f"zendar-sim-{profile.name}", backend=self.backend, overwrite=True)
        truth = build_scene(profile, self.seed, self.index)
        origin = {"lat_deg": truth.enu.lat_deg, "lon_deg": truth.enu.lon_deg, "height_m": truth.enu.height_m}
        calibration = ego_model.calibration(profile)
        # A store already at its final path is complete but lacks its withheld ground truth
        # (interrupted between the two writes): simulate it again to get the labels.
        rewrite = writer.scene_path(self.scene_id).exists()
        with writer.scene(self.scene_id, enu_origin=origin, calibration=calibration, overwrite=rewrite) as scene:
            labels = write_scene(scene, truth, profile, self.seed, self.index, with_labels=not self.withhold)
        if self.withhold:
            self.gt_path.parent.mkdir(exist_ok=True)
            write_json_atomic(self.gt_path, _frames(self.scene_id, labels, truth, profile))


def _run_task(task: _SceneTask) -> str:
    """Run ``task``; any failure comes back naming the scene (picklable, so it crosses processes)."""
    try:
        task.run()
    except ZendarError as exc:
        raise ZendarError(f"{task.scene_id}: {exc}") from exc
    except Exception as exc:
        raise SceneSynthesisError(task.scene_id, f"{type(exc).__name__}: {exc}") from exc
    return task.scene_id


def _init_worker(threads: int) -> None:
    """Worker set-up: leave Ctrl-C to the parent, and cap numba and BLAS/OpenMP threads."""
    global _THREAD_LIMITS
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    import numba
    from threadpoolctl import threadpool_limits

    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    _THREAD_LIMITS = threadpool_limits(limits=threads)  # kept alive: the limits hold while it exists


_THREAD_LIMITS = None


def _run_in_workers(out: pathlib.Path, todo: list[_SceneTask], jobs: int, threads: int, bar: tqdm) -> None:
    """Run ``todo`` on ``jobs`` spawned processes, handing out one scene per free worker.

    After a scene fails no new one is started, the scenes in progress are
    finished (kept for the re-run), and the first failure is raised. Ctrl-C
    stops every worker at once; their hidden temporary stores are removed.
    """
    outcomes: queue.SimpleQueue = queue.SimpleQueue()
    pool = multiprocessing.get_context("spawn").Pool(jobs, initializer=_init_worker, initargs=(threads,))
    try:
        pending = iter(todo)
        in_flight = 0
        failure: BaseException | None = None
        for task in itertools.islice(pending, jobs):
            pool.apply_async(_run_task, (task,), callback=outcomes.put, error_callback=outcomes.put)
            in_flight += 1
        while in_flight:
            outcome = outcomes.get()
            in_flight -= 1
            if isinstance(outcome, BaseException):
                failure = failure or outcome
            else:
                bar.update()
            task = next(pending, None) if failure is None else None
            if task is not None:
                pool.apply_async(_run_task, (task,), callback=outcomes.put, error_callback=outcomes.put)
                in_flight += 1
        pool.close()
    except BaseException:
        # Killed workers leave hidden temporary stores, never a scene at its final path.
        pool.terminate()
        pool.join()
        _remove_interrupted(out)
        raise
    pool.join()
    if failure is not None:
        raise failure


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


__all__ = ["DATASET_JSON", "SceneSynthesisError", "synthesize_dataset", "split_scene_ids", "usable_cpus"]
