"""Command line of ``zendar-bench``.

    zendar-bench [run] [--quick] [--config tiny|demo|gpu|paper] [--data DIR] [--out DIR] [--seeds N] [--jobs N]
                 [--ablations] [--device cpu|cuda] [--scheduler ADDRESS] [--allow-slow]
    zendar-bench verify [--out DIR] [--device cpu|cuda]
    zendar-bench autolabels ROOT --out DIR [--split S] [--no-quality] [--threshold-db DB] [--scheduler ADDRESS]
    zendar-bench fit-chain ROOT [--split S] [--sweep]

Without a command, ``zendar-bench`` is ``zendar-bench run``. Exit statuses as every command of the
package: 0 done, 2 a problem with the user's files or arguments (one line, nothing lost), 1 an
environment failure, 130 Ctrl-C (``zendar_dataset.cli.common``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from zendar_dataset.cli.arguments import DEVICES, seed_count, whole_number
from zendar_dataset.cli.common import run_cli
from zendar_dataset.cluster import SCHEDULER_ENV, DaskCluster, connected, refuse_url_output, scheduler_address
from zendar_dataset.detection.static_scene import DEFAULT_THRESHOLD_DB as SAR_THRESHOLD_DB
from zendar_dataset.errors import ZendarError
from zendar_dataset.worker_pool import usable_cpus

from zendar_baselines.bench import ranks
from zendar_baselines.bench.configs import CONFIGS, get_config
from zendar_baselines.bench.paper_guard import check_paper_config_fits

DEFAULT_OUT = "zendar-bench-out"
DEFAULT_CONFIG = "demo"
QUICK_CONFIG = "tiny"
MAX_SEEDS = 100

RUN_DESCRIPTION = (
    "Reproduce Table 1 of the paper: CFAR with the SAR mask, and FPN-ResNet-34 and zoom-out "
    "DenseNet-37/-67 trained supervised-only and pretrained on automatic labels then fine-tuned; every row "
    "scored on the test split by the official evaluator. Finished steps are reused, so an interrupted run "
    "resumes. 'zendar-bench verify' re-scores a finished run from its checkpoints."
)


def _common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default=DEFAULT_OUT, help=f"run directory (default: ./{DEFAULT_OUT})")
    parser.add_argument("--device", default="cpu", choices=DEVICES, help="where the CNNs run (default: cpu)")


def _run_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--quick", action="store_true",
                        help=f"a short run: the {QUICK_CONFIG} config unless --config is given, 1 seed unless --seeds is")
    parser.add_argument("--config", choices=tuple(CONFIGS), default=None,
                        help=f"training and data configuration (default: {DEFAULT_CONFIG}; with --quick: {QUICK_CONFIG})")
    parser.add_argument("--data", default=None,
                        help="dataset root to use, simulated there when absent (default: a cache directory under "
                        "$XDG_CACHE_HOME/zendar-dataset/bench); on a dataset without manual labels (an imported "
                        "release) only automatic labels, the CFAR predictions and pretraining run, the rest is listed "
                        "as skipped")
    parser.add_argument("--seeds", type=seed_count(MAX_SEEDS), default=None,
                        help="training seeds per CNN row; mean and std over them (default: the config's; 1 with --quick)")
    parser.add_argument("--jobs", "-j", type=whole_number("--jobs", 1), default=None, metavar="N",
                        help="worker processes training CNN seeds at once, one thread each (default: the usable CPUs, "
                        "at most the seeds left; 1 = in this process, and always 1 with --device cuda); the results "
                        "do not depend on it")
    parser.add_argument("--ablations", action="store_true",
                        help="also measure what two changes of the chain moved and what optional input channels add: "
                        "the CFAR row with the SAR reading alone as its static-scene test, and FPN ResNet-34 "
                        "supervised-only trained on CFAR-gated targets, or with the antennas' phase differences, or "
                        "with every cell's Doppler-test residual as extra input channels, each against its Table 1 row "
                        "by paired intervals (ablations.md; adds 3 rows of the config's seeds)")
    parser.add_argument("--scheduler", default=None, metavar="ADDRESS",
                        help="simulate, automatically label and CFAR-predict the dataset's scenes on the Dask "
                        "cluster of this "
                        "scheduler (tcp://host:8786; "
                        f"default: ${SCHEDULER_ENV} when set); the dataset's directory must be one every worker sees "
                        "(docs/cluster.md); the results do not depend on it")
    parser.add_argument("--allow-slow", action="store_true",
                        help="run the paper config on this machine's CPUs alone (refused by default: its projected "
                        "time, in the message, is weeks)")
    _common(parser)
    parser.set_defaults(func=_bench)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="zendar-bench", description=RUN_DESCRIPTION)
    _run_arguments(parser)  # without a command, zendar-bench [run's options] is run
    commands = parser.add_subparsers(dest="command", metavar="[COMMAND]")

    run = commands.add_parser("run", help="reproduce Table 1 (the command when none is given)", description=RUN_DESCRIPTION)
    _run_arguments(run)

    verify = commands.add_parser(
        "verify",
        help="re-score a finished run from its checkpoints",
        description="Re-score a finished run from its checkpoints and say whether every row reproduces its "
        "recorded AP within its tolerance per band: 0.01 for the CFAR row (exact on every machine tried), 0.015 for "
        "the CNN rows (their measured spread across CPUs) (exit 0 when all do, 1 when one does not).",
    )
    _common(verify)
    verify.set_defaults(func=_verify)

    autolabels = commands.add_parser(
        "autolabels",
        help="write the automatic labels of a split to a side store, with their quality",
        description="Write the automatic labels (paper §2.3: CFAR + DOA + the SAR static-scene test, segments grown "
        "in the range-Doppler map, clusters mixing moving and static points marked uncertain) of a split to a "
        "versioned side store beside the dataset, and their precision and recall against the manual labels per "
        "band where the scenes have labels. Re-running resumes.",
    )
    autolabels.add_argument("root", help="dataset root")
    autolabels.add_argument("--out", required=True, help="output directory: new, empty, or one this command wrote for this "
                            "dataset (its store/ and quality.json; anything else in it is refused); never inside ROOT")
    autolabels.add_argument("--split", default="train", help="split to label (default: train)")
    autolabels.add_argument("--no-quality", action="store_true",
                            help="skip the comparison with the manual labels (needed for scenes without labels)")
    autolabels.add_argument("--threshold-db", type=float, default=None, metavar="DB",
                            help="the SAR static-scene test's threshold: a point is dynamic below it (default: "
                            f"{SAR_THRESHOLD_DB:g} dB, docs/baselines.md); recorded in the store")
    autolabels.add_argument("--scheduler", default=None, metavar="ADDRESS",
                            help="label the scenes on the Dask cluster of this scheduler, one task per scene "
                            f"(tcp://host:8786; default: ${SCHEDULER_ENV} when set); ROOT and --out must be directories "
                            "every worker sees at the same path (docs/cluster.md); the labels do not depend on it")
    autolabels.set_defaults(func=_autolabels)

    fit_chain = commands.add_parser(
        "fit-chain",
        help="fit the detection chain's SAR threshold, cluster radius and centre offset on a split",
        description="Fit the detection chain's SAR threshold, cluster radius and centre offset on a split's CFAR points, "
        "checked on the validation split (never the test split).",
    )
    fit_chain.add_argument("root", help="dataset root")
    fit_chain.add_argument("--split", default="train", help="split to fit on (default: train; test is refused)")
    fit_chain.add_argument("--sweep", action="store_true", help="also report the chain's AP over a grid of thresholds")
    fit_chain.set_defaults(func=_fit_chain)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is not None and argv[0] != args.command:
        # The options before a command were parsed as run's, and the command's own defaults would
        # silently replace them (zendar-bench --out X verify would verify ./zendar-bench-out).
        parser.error(f"{args.command!r} must come first: the options before it are run's")
    return run_cli(lambda: args.func(args))


def _check_device(device: str) -> None:
    if device == "cuda":
        import torch

        if not torch.cuda.is_available():
            raise ZendarError("--device cuda: no CUDA device is available to torch here; use --device cpu")


def _bench(args: argparse.Namespace) -> int:
    from zendar_baselines.bench.run import BenchOptions, run_bench

    _check_device(args.device)
    config = get_config(args.config or (QUICK_CONFIG if args.quick else DEFAULT_CONFIG))
    seeds = args.seeds or (1 if args.quick else config.seeds)
    scheduler = scheduler_address(args.scheduler)
    check_paper_config_fits(config, args.device, scheduler, args.allow_slow, usable_cpus())
    if scheduler is not None:
        refuse_url_output(args.out, "--out")  # the automatic labels' store is written by the workers
        if args.data is not None:
            refuse_url_output(args.data, "--data")
        DaskCluster.connect(scheduler).close()  # it answers before anything is written
    data = None if args.data is None else Path(args.data).absolute()
    options = BenchOptions(config=config, data=data, out=Path(args.out), seeds=seeds, device=args.device, jobs=args.jobs,
                           ablations=args.ablations, scheduler=scheduler)
    results = run_bench(options)
    if not ranks.is_main():  # under torchrun: rank 0 wrote the run and says so
        return 0
    if results.get("manual_labels") is False:
        print(f"wrote {Path(args.out) / 'table.md'}, results.json and rows/ (no manual labels: the steps that need none)")
    else:
        print(f"wrote {Path(args.out) / 'table.md'}, table.csv, results.json, pr_*.png, bev.png and rows/")
    return 0


def _verify(args: argparse.Namespace) -> int:
    from zendar_baselines.bench.verify import verify_run

    _check_device(args.device)
    report = verify_run(Path(args.out), args.device)
    print(report.text)
    return 0 if report.reproduced else 1


def _autolabels(args: argparse.Namespace) -> int:
    from zendar_dataset.format.reader import open_dataset
    from zendar_baselines.bench.autolabels import refuse_foreign_out, write_auto_labels
    from zendar_baselines.labels.masks import MaskParams

    refuse_foreign_out(Path(args.out), args.root)  # before the dataset is read or anything written
    index = open_dataset(args.root)
    scene_ids = index.scene_ids(args.split)
    if not scene_ids:
        raise ZendarError(f"{args.root}: split {args.split!r} has no scenes")
    if not args.no_quality:
        unlabelled = [scene for scene in scene_ids if index.open_scene(scene).labels() is None]
        if unlabelled:
            raise ZendarError(f"{args.root}: {', '.join(unlabelled)} of split {args.split!r} have no labels to "
                              "measure the automatic labels against; add --no-quality")
    with connected(scheduler_address(args.scheduler)) as cluster:  # it answers before anything is written
        document = write_auto_labels(index, scene_ids, Path(args.out), quality=not args.no_quality, cluster=cluster,
                                     params=MaskParams().with_sar_threshold(args.threshold_db))
    if document is not None:
        print(document["table"])
    print(f"wrote the automatic labels of {len(scene_ids)} scenes to {Path(args.out) / 'store'}")
    return 0


def _fit_chain(args: argparse.Namespace) -> int:
    import json

    from zendar_baselines.classical.chain_fit import fit_chain_params

    params, summary = fit_chain_params(args.root, args.split, sweep=args.sweep)
    print(json.dumps({"summary": summary, "params": params.to_json()}, indent=1))
    return 0
