"""``zendar-data synth OUT``: write a synthetic format-v1 dataset."""

from __future__ import annotations

import argparse

from zendar_dataset.cli.arguments import DEVICES, split_ratios, whole_number
from zendar_dataset.cli.common import writing
from zendar_dataset.cluster import SCHEDULER_ENV, refuse_url_output, scheduler_address
from zendar_dataset.errors import ZendarError
from zendar_dataset.sim.generate import MAX_SCENE_DURATION_S, MAX_SCENES, MAX_SEED
from zendar_dataset.sim.profiles import MIN_SCENE_DURATION_S, PROFILES


def default_jobs(n_scenes: int) -> int:
    """Worker processes ``synth`` uses without ``--jobs``: the usable CPUs, or 1 for fewer
    scenes than twice the CPUs, where workers cannot pay off.

    A spawned worker costs seconds before its first scene (interpreter, imports, compiled
    kernels loaded), and scenes are handed out whole, so with few scenes per worker the last
    round leaves CPUs idle. Measured on the 2-core reference machine (``benchmarks/bench_sim.py``):
    3 ``tiny`` scenes took 4.7 s in one process against 5.5-6.3 s with 2 workers (idle), 39 s
    against 59 s (load average 10); 12 ``tiny`` scenes 59 s against 38 s (load average 5); the
    5 ``demo`` scenes 2 min 34 s against 1 min 33 s.
    """
    from zendar_dataset.sim.generate import usable_cpus

    cpus = usable_cpus()
    return 1 if n_scenes < 2 * cpus else cpus


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "synth",
        help="simulate a dataset (radar cubes, SAR, lidar, camera, tracklog, labels)",
        description="Simulate urban drives and write them as a format-v1 dataset. Re-running into the same OUT "
        "with the same settings resumes an interrupted run.",
    )
    parser.add_argument("out", metavar="OUT", help="dataset root to create (new or empty, or an interrupted run)")
    parser.add_argument("--profile", choices=sorted(PROFILES), default="demo", help="size of the simulation (default: demo)")
    parser.add_argument("--scenes", type=whole_number("--scenes", 1, MAX_SCENES), default=None,
                        help=f"number of scenes, 1 to {MAX_SCENES:,} (default: the profile's)")
    parser.add_argument("--seed", type=whole_number("--seed", 0, MAX_SEED), default=0,
                        help=f"random seed, 0 to {MAX_SEED:,} (2**32 - 1; default: 0)")
    # Range checked with the profile (SimProfile.with_duration, then synthesize_dataset), before anything is
    # written: one message for every duration problem, whichever way the dataset is made.
    parser.add_argument("--duration-s", type=float, default=None, metavar="SECONDS",
                        help=f"length of each scene (default: the profile's; {MIN_SCENE_DURATION_S:g} to "
                        f"{MAX_SCENE_DURATION_S:,}, a multiple of 0.1); recorded with the profile in OUT/simulation.json")
    parser.add_argument("--split-ratios", type=split_ratios, default=(0.6, 0.2, 0.2),
                        help="train,val,test shares: finite, 0 or more, with a positive sum (default: 0.6,0.2,0.2)")
    parser.add_argument("--backend", choices=("zarr", "hdf5"), default="zarr", help="scene store format (default: zarr)")
    parser.add_argument("--withhold-test-labels", action="store_true",
                        help="write test scenes without labels and their ground truth to OUT/test_ground_truth.json")
    parser.add_argument("--jobs", "-j", type=whole_number("--jobs", 1), default=None, metavar="N",
                        help="worker processes, one scene each at a time (default: the usable CPUs, at most the "
                        "scenes left, but 1 for fewer scenes than twice the CPUs, where workers cost more than "
                        "they save; 1 = in this process); the output does not depend on it")
    parser.add_argument("--device", choices=DEVICES, default="cpu",
                        help="where SAR images are backprojected: cpu (numba kernel, default) or cuda (torch on the "
                        "GPU: the same sum, equal to rounding; recorded in OUT/simulation.json). Each worker "
                        "process holds its own GPU memory: lower --jobs if the GPU runs out")
    parser.add_argument("--scheduler", default=None, metavar="ADDRESS",
                        help="run the scenes on the Dask cluster of this scheduler (tcp://host:8786; default: "
                        f"${SCHEDULER_ENV} when set, else this machine), one task per scene; OUT must be a directory "
                        "every worker sees at the same path (docs/cluster.md); the output does not depend on it")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from zendar_dataset.sim.generate import synthesize_dataset
    from zendar_dataset.sim.profiles import get_profile

    profile = get_profile(args.profile)
    if args.duration_s is not None:
        profile = profile.with_duration(args.duration_s)
    n_scenes = profile.default_scenes if args.scenes is None else args.scenes
    scheduler = scheduler_address(args.scheduler)
    if scheduler is not None:
        refuse_url_output(args.out, "OUT")
        if args.jobs is not None:
            raise ZendarError(f"--jobs does not apply with a Dask scheduler ({scheduler}, from "
                              f"{'--scheduler' if args.scheduler is not None else '$' + SCHEDULER_ENV}): "
                              "its workers run the scenes; drop one of the two")
        jobs = 1
    else:
        jobs = default_jobs(n_scenes) if args.jobs is None else args.jobs
    with writing(args.out):
        out = synthesize_dataset(
            args.out,
            profile=profile,
            n_scenes=args.scenes,
            seed=args.seed,
            split_ratios=args.split_ratios,
            backend=args.backend,
            progress=not args.quiet,
            withhold_test_labels=args.withhold_test_labels,
            jobs=jobs,
            sar_device=args.device,
            scheduler=scheduler,
        )
    print(f"wrote {out}")
    return 0
