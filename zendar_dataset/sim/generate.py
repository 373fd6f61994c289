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
The API runs in this process unless asked for workers, because ``spawn``
re-runs the caller's main script in each worker: a call at the top level of
a script without an ``if __name__ == "__main__":`` guard is refused at once
rather than started, and a worker that dies (at start-up or later) fails the
run instead of being replaced.

On a Dask cluster (``scheduler``, :mod:`zendar_dataset.cluster`) each scene is one task; a scene
whose worker dies is simulated again on another worker, and the bytes are the same as here: a
scene's random streams depend only on the seed and its index (:func:`zendar_dataset.sim.scene.stream_rng`).
"""

from __future__ import annotations

import ast
import json
import math
import numbers
import os
import pathlib
import sys
from dataclasses import dataclass

from tqdm import tqdm

from zendar_dataset.cluster import DaskCluster, connected, refuse_url_output
from zendar_dataset.errors import ZendarError
from zendar_dataset.format.schema import BACKEND_SUFFIX, DATASET_JSON, frame_id
from zendar_dataset.atomic_files import write_json_atomic
from zendar_dataset.format.writer import DatasetWriter
from zendar_dataset.sim import ego as ego_model
from zendar_dataset.sim.profiles import SimProfile, get_profile
from zendar_dataset.sim.scene import build_scene, write_scene
from zendar_dataset.temporary_files import remove_stale_temporaries
from zendar_dataset.worker_pool import run_in_workers, usable_cpus

SIDECAR = "simulation.json"
GROUND_TRUTH_DIR = "ground_truth"
TEST_GROUND_TRUTH = "test_ground_truth.json"

#: Most scenes in one dataset: their ids (``scene-0000``...) keep four digits, so they sort in scene order.
MAX_SCENES = 10_000
#: Largest seed: a scene's random streams are seeded with ``[seed, scene index, stream]``, and numpy splits a
#: larger seed into several 32-bit words, which would make ``(seed, scene)`` pairs share streams.
MAX_SEED = 2**32 - 1
#: Longest scene in seconds (one hour): a scene is one task, simulated and written by one process.
MAX_SCENE_DURATION_S = 3600


def split_scene_ids(n_scenes: int, split_ratios: tuple[float, float, float]) -> dict[str, list[str]]:
    """Scene ids ``scene-0000``... assigned in order to train, val and test by ``split_ratios``.

    Raises
    ------
    ZendarError
        Unless ``split_ratios`` are three finite numbers of 0 or more with a positive, finite sum.
    """
    ratios = [float(r) for r in split_ratios]
    # The sum is checked as well: the shares are divided by it, and finite shares can add up to inf.
    if len(ratios) != 3 or not all(math.isfinite(r) and r >= 0 for r in ratios) or not 0 < sum(ratios) < math.inf:
        raise ZendarError(
            f"split ratios must be three finite numbers of 0 or more (train, val, test) with a positive, finite sum, "
            f"got {split_ratios!r}"
        )
    total = sum(ratios)
    n_val = int(round(n_scenes * ratios[1] / total))
    n_test = min(n_scenes - n_val, int(round(n_scenes * ratios[2] / total)))
    n_train = n_scenes - n_val - n_test
    ids = [f"scene-{i:04d}" for i in range(n_scenes)]
    return {"train": ids[:n_train], "val": ids[n_train : n_train + n_val], "test": ids[n_train + n_val :]}


def _settings(profile: SimProfile, n_scenes: int, seed: int, split_ratios, backend: str, withhold: bool,
              sar_device: str | None) -> dict:
    settings = {
        "generator": "zendar_dataset.sim",
        "profile": profile.to_json(),
        "scenes": int(n_scenes),
        "seed": int(seed),
        "split_ratios": [float(r) for r in split_ratios],
        "backend": backend,
        "withhold_test_labels": bool(withhold),
    }
    # Recorded only off the default, so records written before the option existed still resume:
    # another backend rounds differently, and one dataset should not mix the two.
    if sar_device is not None:
        settings["sar_device"] = sar_device
    return settings


def check_sar_device(device: str | None) -> str | None:
    """``None`` for the numba kernel (``None`` or ``"cpu"``), else a CUDA device name that torch can use.

    Raises
    ------
    ZendarError
        For anything else, or CUDA without a usable device.
    """
    if device is None or device == "cpu":
        return None
    if not (isinstance(device, str) and (device == "cuda" or device.startswith("cuda:"))):
        raise ZendarError(f"SAR device must be 'cpu' or 'cuda' (or 'cuda:N'), got {device!r}")
    import torch

    try:
        usable = torch.cuda.is_available() and torch.device(device).index in (None, *range(torch.cuda.device_count()))
    except RuntimeError:
        usable = False
    if not usable:
        raise ZendarError(f"SAR device {device!r}: torch sees no such CUDA device on this machine")
    return device


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


def _remove_interrupted(out: pathlib.Path, cluster: DaskCluster | None = None) -> None:
    """Delete the temporary scene stores of writers that are gone (only this package's, see temporary_files.py);
    on a cluster, those of its live workers are kept too (their process ids are on other hosts)."""
    if cluster is None:
        remove_stale_temporaries(out / "scenes")
    else:
        cluster.remove_orphaned_temporaries(out / "scenes")


class SceneSynthesisError(RuntimeError):
    """Simulating or writing one scene failed; ``scene_id`` names it and the message carries the cause."""

    def __init__(self, scene_id: str, message: str) -> None:
        super().__init__(f"{scene_id}: {message}")
        self.scene_id = scene_id
        self.cause_message = message

    def __reduce__(self):
        # Rebuilt from both arguments when it crosses from a worker process.
        return (type(self), (self.scene_id, self.cause_message))


def synthesize_dataset(
    out: str | os.PathLike,
    profile: str | SimProfile = "demo",
    n_scenes: int | None = None,
    seed: int = 0,
    split_ratios: tuple[float, float, float] = (0.6, 0.2, 0.2),
    backend: str = "zarr",
    progress: bool = True,
    withhold_test_labels: bool = False,
    jobs: int = 1,
    sar_device: str | None = None,
    scheduler: str | None = None,
) -> pathlib.Path:
    """Write a synthetic dataset to ``out`` (or finish an interrupted one).

    Parameters
    ----------
    out : path-like
        Dataset root; must be new, empty, or a previous run with the same settings.
    profile : {"tiny", "demo", "paper"} or SimProfile
    n_scenes : int, optional
        1 to :data:`MAX_SCENES`; default: the profile's ``default_scenes``.
    seed : int
        0 to :data:`MAX_SEED`. Same seed and profile give byte-identical arrays, whatever ``jobs``.
    split_ratios : (train, val, test)
    backend : {"zarr", "hdf5"}
    progress : bool
        Show a tqdm progress bar over scenes (it advances as each scene is finished).
    withhold_test_labels : bool
        Write test scenes without ``labels/moving_cars`` and put their ground
        truth in ``OUT/test_ground_truth.json`` (the ``export-gt`` layout).
    jobs : int
        Worker processes, each writing one scene at a time; never more than the
        scenes left to write. ``1`` (the default) simulates in this process;
        :func:`usable_cpus` is the useful maximum. Each worker's numba and BLAS
        threads are capped so that ``jobs * threads`` does not exceed the usable
        CPUs. Workers are started with ``spawn``, which re-runs the main script:
        from a script, call with ``jobs > 1`` under ``if __name__ == "__main__":``.
    sar_device : {None, "cpu", "cuda", "cuda:N"}
        Where SAR images are backprojected: the numba kernel on the CPU (``None``, ``"cpu"``) or
        the torch backend on a GPU, which computes the same float32 sum (equal to rounding, so
        not byte-identical to a CPU run; a GPU run is recorded in ``simulation.json``).
    scheduler : str, optional
        A Dask scheduler's address (``tcp://host:8786``): one task per scene on its workers instead
        of ``jobs`` local processes (``jobs`` must then be 1). ``out`` must be a directory every worker
        sees at the same path (checked; a URL is refused), and the scheduler must answer before
        anything is written. The bytes are the same as without one (docs/cluster.md).

    Returns
    -------
    pathlib.Path
        ``out``.

    Raises
    ------
    ZendarError
        When ``out`` holds something else, or an argument is invalid (more than :data:`MAX_SCENES`
        scenes, a seed outside 0 to :data:`MAX_SEED`, scenes longer than :data:`MAX_SCENE_DURATION_S`), or
        ``jobs > 1`` is asked from the top level of an unguarded main script,
        or ``out`` is a URL or a directory some worker of ``scheduler`` does not see.
    zendar_dataset.cluster.ClusterUnavailable
        When ``scheduler`` does not answer or has no worker (nothing written).
    SceneSynthesisError
        When simulating a scene fails or its worker process dies (the message
        names the scene and the cause). No scene is started after it; the ones
        finished (also those in progress in other workers) are kept and a re-run
        resumes.
    KeyboardInterrupt
        On Ctrl-C, also when it lands inside a compiled kernel; workers are
        stopped and their temporary stores removed.
    """
    profile = get_profile(profile)
    n_scenes = profile.default_scenes if n_scenes is None else int(n_scenes)
    _check_size(n_scenes, seed, profile)
    if backend not in BACKEND_SUFFIX:
        raise ZendarError(f"backend must be one of {sorted(BACKEND_SUFFIX)}, got {backend!r}")
    if isinstance(jobs, bool) or not isinstance(jobs, numbers.Integral) or jobs < 1:
        raise ZendarError(f"jobs must be a positive integer, got {jobs!r}")
    jobs = int(jobs)
    if scheduler is not None:
        refuse_url_output(out, "the output")
        if jobs != 1:
            raise ZendarError(f"jobs={jobs} does not apply with a Dask scheduler ({scheduler}): its workers run the scenes")
    sar_device = check_sar_device(sar_device)
    if jobs > 1:
        _refuse_unguarded_main(jobs)
    splits = split_scene_ids(n_scenes, split_ratios)
    out = pathlib.Path(out)
    # Connected before the output is touched: a scheduler that does not answer leaves nothing behind.
    with connected(scheduler) as cluster:
        _synthesize_into(out, profile, n_scenes, seed, split_ratios, backend, progress, withhold_test_labels, jobs,
                         sar_device, splits, cluster)
    return out


def _check_size(n_scenes: int, seed: int, profile: SimProfile) -> None:
    """Refuse a scene count, seed or scene duration out of range, before anything is written.

    Raises
    ------
    ZendarError
        Naming the value and its range (:data:`MAX_SCENES`, :data:`MAX_SEED`, :data:`MAX_SCENE_DURATION_S`).
    """
    if not 1 <= n_scenes <= MAX_SCENES:
        raise ZendarError(f"the number of scenes must be between 1 and {MAX_SCENES:,}, got {n_scenes}")
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or not 0 <= seed <= MAX_SEED:
        raise ZendarError(f"the seed must be a whole number between 0 and {MAX_SEED:,} (2**32 - 1), got {seed!r}")
    if profile.scene_duration_s > MAX_SCENE_DURATION_S:
        raise ZendarError(
            f"the scene duration must be at most {MAX_SCENE_DURATION_S:,} s, got {profile.scene_duration_s:g} s"
        )


def _synthesize_into(out: pathlib.Path, profile: SimProfile, n_scenes: int, seed: int, split_ratios, backend: str,
                     progress: bool, withhold_test_labels: bool, jobs: int, sar_device: str | None,
                     splits: dict[str, list[str]], cluster: DaskCluster | None) -> None:
    """:func:`synthesize_dataset` once its arguments are checked (and its cluster connected)."""
    _prepare_output(out, _settings(profile, n_scenes, seed, split_ratios, backend, withhold_test_labels, sar_device))
    _remove_interrupted(out, cluster)
    writer = DatasetWriter(out, f"zendar-sim-{profile.name}", backend=backend, overwrite=True)
    test_ids = set(splits["test"])
    todo = []
    for index in range(n_scenes):
        task = _SceneTask(out, profile, seed, backend, index, withhold_test_labels and f"scene-{index:04d}" in test_ids,
                          sar_device)
        if not task.is_complete(writer):
            todo.append(task)
    bar = tqdm(total=n_scenes, initial=n_scenes - len(todo), desc=f"synth {profile.name}", unit="scene", disable=not progress)
    with bar:
        cpus = usable_cpus()
        n_jobs = min(jobs, len(todo))
        if cluster is not None and todo:
            with cluster.shared_directory(out / "scenes") as shared:
                cluster.run(
                    _run_task, todo, shared=shared, on_done=lambda task, scene_id: bar.update(),
                    worker_died=lambda task: SceneSynthesisError(
                        task.scene_id, "the Dask workers running it died (killed, out of memory, or their node lost) "
                        "as many times as the scheduler allows (distributed.scheduler.allowed-failures)"),
                    # Workers stopped mid-scene leave hidden temporary stores, never a scene at its final path.
                    on_interrupt=lambda: _remove_interrupted(out, cluster))
        elif n_jobs <= 1:
            for task in todo:
                _run_task(task)
                bar.update()
        else:
            run_in_workers(
                _run_task, todo, n_jobs, max(1, cpus // n_jobs), on_done=lambda task, scene_id: bar.update(),
                worker_died=lambda task: SceneSynthesisError(
                    task.scene_id, "a worker process died (killed by a signal, out of memory, or failed at start-up)"),
                # Killed workers leave hidden temporary stores, never a scene at its final path.
                on_interrupt=lambda: _remove_interrupted(out))
    writer.finalize(splits)
    if withhold_test_labels:
        frames: dict = {}
        for scene_id in splits["test"]:
            frames.update(json.loads((out / GROUND_TRUTH_DIR / f"{scene_id}.json").read_text(encoding="utf-8")))
        write_json_atomic(out / TEST_GROUND_TRUTH, {"frames": frames})


@dataclass(frozen=True)
class _SceneTask:
    """One scene to simulate and write (picklable, sent to a worker process)."""

    out: pathlib.Path
    profile: SimProfile
    seed: int
    backend: str
    index: int
    withhold: bool
    sar_device: str | None = None

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
            labels = write_scene(scene, truth, profile, self.seed, self.index, with_labels=not self.withhold,
                                 sar_device=self.sar_device)
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
        if _caused_by_interrupt(exc):
            # Ctrl-C inside a compiled kernel surfaces as a SystemError around the KeyboardInterrupt.
            raise KeyboardInterrupt from exc
        raise SceneSynthesisError(task.scene_id, f"{type(exc).__name__}: {exc}") from exc
    return task.scene_id


def _caused_by_interrupt(exc: BaseException) -> bool:
    """Whether a KeyboardInterrupt is in the cause or context chain of ``exc``."""
    seen: set[int] = set()
    link: BaseException | None = exc
    while link is not None and id(link) not in seen:
        if isinstance(link, KeyboardInterrupt):
            return True
        seen.add(id(link))
        link = link.__cause__ or link.__context__
    return False


def _refuse_unguarded_main(jobs: int) -> None:
    """Refuse ``jobs > 1`` when called from the top level of an unguarded main script.

    ``spawn`` workers re-run the main script (as ``__mp_main__``); without an
    ``if __name__ == "__main__":`` guard each worker would call this function
    again and die at start-up. Detected by finding the main script's
    module-level frame on the stack and checking, in its syntax tree, whether
    the executing line sits in the body of such a guard (at any depth).
    Interactive sessions, ``python -c`` and notebooks have no script to re-run
    and are not refused.
    """
    main = sys.modules.get("__main__")
    path = getattr(main, "__file__", None)
    if main is None or path is None:
        return
    frame = sys._getframe(1)
    while frame is not None and not (frame.f_globals is vars(main) and frame.f_code.co_name == "<module>"):
        frame = frame.f_back
    if frame is None:
        return
    try:
        tree = ast.parse(pathlib.Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, SyntaxError, ValueError):
        return  # no source to inspect; a worker that dies at start-up still fails the run
    line = frame.f_lineno
    for node in ast.walk(tree):
        if _is_main_guard(node) and node.body[0].lineno <= line <= (node.body[-1].end_lineno or line):
            return
    raise ZendarError(
        f"synthesize_dataset(jobs={jobs}) was called at the top level of {path} (line {line}) without an "
        "'if __name__ == \"__main__\":' guard; worker processes re-run that script and would start again. "
        "Put the call under the guard, or use jobs=1 (the default, in this process)"
    )


def _is_main_guard(statement: ast.AST) -> bool:
    """Whether ``statement`` is ``if __name__ == "__main__":`` (either operand order)."""
    if not isinstance(statement, ast.If) or not isinstance(statement.test, ast.Compare):
        return False
    test = statement.test
    if len(test.ops) != 1 or not isinstance(test.ops[0], ast.Eq):
        return False
    operands = [test.left, test.comparators[0]]
    names = [o for o in operands if isinstance(o, ast.Name) and o.id == "__name__"]
    constants = [o for o in operands if isinstance(o, ast.Constant) and o.value == "__main__"]
    return len(names) == 1 and len(constants) == 1


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


__all__ = [
    "DATASET_JSON", "MAX_SCENES", "MAX_SCENE_DURATION_S", "MAX_SEED", "SceneSynthesisError", "synthesize_dataset",
    "split_scene_ids", "usable_cpus",
]
