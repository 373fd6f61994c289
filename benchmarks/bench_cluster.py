"""Claim: scenes on a local Dask cluster (``zendar-data synth --scheduler``) come about as fast as on
the package's own worker processes (``--jobs``), and Dask's cost per task is small beside a scene's.

Run: python benchmarks/bench_cluster.py [--profile tiny] [--scenes 6] [--repeats 2] [--tasks 500] [--label-scenes 10]

1. Scenes per hour: the same ``--scenes`` scenes of ``--profile`` (seed 0) written by
   :func:`synthesize_dataset` in this process (``jobs=1``), on 2 spawned worker processes
   (``jobs=2``, the pool started by each run, as ``zendar-data synth`` does), and on a
   ``distributed.LocalCluster`` of 1 and of 2 one-thread worker processes started once beforehand
   and warmed by one untimed run (a standing cluster, as on a batch system); its start-up is
   printed apart. Every side's numba threads fill the CPUs: 1 side alone uses them all, 2 workers half
   each.
   Interleaved, ``--repeats`` times; each run writes a new directory, and every output is checked
   byte-identical to the first.
2. Automatic labels per hour (``zendar-bench autolabels --scheduler``): the training scenes of a dataset
   of ``--profile`` (``--label-scenes`` scenes, seed 0) labelled by :func:`write_auto_labels` in this
   process and on the 1- and 2-worker clusters, each run into a new store, every store checked
   byte-identical (scene files and quality) to the one made in this process.
3. Scheduling overhead per task: ``--tasks`` calls of a task that does nothing (``abs``) in this
   process, through ``run_in_workers`` on 2 processes (its pool's start included, as each run
   pays it), through :meth:`DaskCluster.run` on the 2-worker cluster (one task per worker thread
   in flight, a probe of the shared directory and the thread caps per task: what the package
   does), and through ``client.map`` with every task submitted at once (Dask's own floor).
"""

from __future__ import annotations

import argparse
import contextlib
import pathlib
import shutil
import tempfile
import time

from harness import Spread, interleaved, print_environment, print_load_after

from zendar_dataset.cluster import DaskCluster
from zendar_dataset.format.reader import open_dataset
from zendar_dataset.sim.generate import synthesize_dataset, usable_cpus
from zendar_dataset.worker_pool import run_in_workers

from zendar_baselines.bench.autolabels import write_auto_labels


def _files(root: pathlib.Path) -> dict[str, bytes]:
    return {str(path.relative_to(root)): path.read_bytes() for path in sorted(root.rglob("*")) if path.is_file()}


class _Side:
    """One side of a timed table: each call writes into a new directory, checked equal to its first."""

    def __init__(self, work: pathlib.Path, name: str) -> None:
        self.work, self.name = work, name
        self.runs = 0
        self.first: dict[str, bytes] | None = None

    def write(self, out: pathlib.Path) -> dict[str, bytes]:
        """Write into ``out``; return the files to compare."""
        raise NotImplementedError

    def __call__(self) -> None:
        self.runs += 1
        out = self.work / f"{self.name}-{self.runs}"
        files = self.write(out)
        if self.first is None:
            self.first = files
        elif files != self.first:
            raise SystemExit(f"{self.name}: run {self.runs} differs from its first")
        shutil.rmtree(out)


class _Synthesis(_Side):
    """The scenes-per-hour table's side: the scenes of ``profile`` written with ``options``."""

    def __init__(self, work: pathlib.Path, name: str, profile: str, n_scenes: int, **options) -> None:
        super().__init__(work, name)
        self.profile, self.n_scenes, self.options = profile, n_scenes, options

    def write(self, out: pathlib.Path) -> dict[str, bytes]:
        synthesize_dataset(out, self.profile, n_scenes=self.n_scenes, seed=0, progress=False, **self.options)
        return _files(out)


def scenes_per_hour(work: pathlib.Path, profile: str, n_scenes: int, repeats: int, clusters: dict[str, str]) -> None:
    sides = {
        "this process (jobs=1)": _Synthesis(work, "jobs1", profile, n_scenes, jobs=1),
        "2 worker processes (jobs=2)": _Synthesis(work, "jobs2", profile, n_scenes, jobs=2),
    }
    for index, (name, address) in enumerate(clusters.items()):
        sides[name] = _Synthesis(work, f"dask{index}", profile, n_scenes, scheduler=address)
    times = interleaved(sides, repeats=repeats, warmup=1)
    reference = sides["this process (jobs=1)"].first
    for name, side in sides.items():
        if side.first != reference:
            raise SystemExit(f"{name}: the scenes differ from the ones written in this process")
    print(f"\n{n_scenes} {profile!r} scenes, seed 0; byte-identical on every side; median (min-max) of {repeats}")
    _print_rates(times, n_scenes)


def _print_rates(times: dict[str, Spread], n_scenes: int) -> None:
    """The table of each side's wall time and scenes per hour."""
    print("| where | wall time (s) | scenes per hour |")
    print("|---|--:|--:|")
    for name, spread in times.items():
        rate = Spread(n_scenes * 3600 / spread.max, n_scenes * 3600 / spread.median, n_scenes * 3600 / spread.min,
                      spread.repeats)
        print(f"| {name} | {spread.text('.1f')} | {rate.text('.0f')} |", flush=True)


class _Labelling(_Side):
    """The automatic-labels table's side: the scenes labelled here or on the cluster at ``address``."""

    def __init__(self, work: pathlib.Path, name: str, root: pathlib.Path, scene_ids: list[str], address: str | None) -> None:
        super().__init__(work, f"labels-{name}")
        self.root, self.scene_ids, self.address = root, scene_ids, address

    def write(self, out: pathlib.Path) -> dict[str, bytes]:
        with contextlib.ExitStack() as stack:
            cluster = None if self.address is None else stack.enter_context(DaskCluster.connect(self.address))
            write_auto_labels(open_dataset(self.root), self.scene_ids, out, cluster=cluster)
        # The manifest holds its creation time and the order the scenes finished in.
        return {name: data for name, data in _files(out).items() if not name.endswith("manifest.json")}


def labels_per_hour(work: pathlib.Path, profile: str, n_scenes: int, repeats: int, clusters: dict[str, str]) -> None:
    root = work / "labelled-dataset"
    synthesize_dataset(root, profile, n_scenes=n_scenes, seed=0, progress=False, jobs=min(2, usable_cpus()))
    scene_ids = open_dataset(root).scene_ids("train")
    sides = {"this process": _Labelling(work, "here", root, scene_ids, None)}
    for index, (name, address) in enumerate(clusters.items()):
        sides[name] = _Labelling(work, f"dask{index}", root, scene_ids, address)
    times = interleaved(sides, repeats=repeats, warmup=1)
    for name, side in sides.items():
        if side.first != sides["this process"].first:
            raise SystemExit(f"{name}: the automatic labels differ from the ones made in this process")
    n = len(scene_ids)
    print(f"\nautomatic labels of the {n} training scenes of {n_scenes} {profile!r} scenes (with their quality); "
          f"byte-identical on every side; median (min-max) of {repeats}")
    _print_rates(times, n)


def _dask_map(cluster: DaskCluster, n_tasks: int) -> None:
    futures = cluster.client.map(abs, range(-n_tasks, 0), pure=False)
    cluster.client.gather(futures)


def overhead_per_task(work: pathlib.Path, cluster: DaskCluster, n_tasks: int, repeats: int) -> None:
    shared_dir = work / "shared"
    shared_dir.mkdir()
    tasks = range(-n_tasks, 0)
    with cluster.shared_directory(shared_dir) as shared:
        sides = {
            "in this process (a loop)": lambda: [abs(task) for task in tasks],
            "run_in_workers, 2 processes (pool start included)": lambda: run_in_workers(
                abs, tasks, 2, 1, on_done=lambda task, result: None, worker_died=lambda task: RuntimeError(task)),
            "DaskCluster.run, 2 workers (the package's path)": lambda: cluster.run(
                abs, tasks, shared=shared, on_done=lambda task, result: None, worker_died=lambda task: RuntimeError(task)),
            "Dask client.map, all at once (Dask's floor)": lambda: _dask_map(cluster, n_tasks),
        }
        times = interleaved(sides, repeats=repeats, warmup=1)
    print(f"\nscheduling overhead: {n_tasks} tasks that do nothing; median (min-max) of {repeats}")
    print("| through | total (s) | per task (ms) |")
    print("|---|--:|--:|")
    for name, spread in times.items():
        print(f"| {name} | {spread.text('.3g')} | {spread.scaled(1e3 / n_tasks).text('.3g')} |", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profile", default="tiny")
    parser.add_argument("--scenes", type=int, default=6)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--tasks", type=int, default=500)
    parser.add_argument("--label-scenes", type=int, default=10)
    args = parser.parse_args()
    from distributed import LocalCluster

    print_environment(["distributed", "dask", "numba", "numpy"])
    print(f"usable CPUs: {usable_cpus()}")
    with tempfile.TemporaryDirectory() as temporary, contextlib.ExitStack() as clusters:
        work = pathlib.Path(temporary)
        addresses = {}
        for n_workers in (1, 2):
            started = time.perf_counter()
            cluster = clusters.enter_context(
                LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=":0"))
            name = f"Dask, {n_workers} worker{'s' * (n_workers > 1)} x 1 thread"
            print(f"start-up of {name}: {time.perf_counter() - started:.1f} s")
            addresses[name] = cluster.scheduler_address
        scenes_per_hour(work, args.profile, args.scenes, args.repeats, addresses)
        labels_per_hour(work, args.profile, args.label_scenes, args.repeats, addresses)
        with DaskCluster.connect(addresses["Dask, 2 workers x 1 thread"]) as cluster:
            overhead_per_task(work, cluster, args.tasks, args.repeats)
    print_load_after()


if __name__ == "__main__":
    main()
