"""``zendar-eval``: score a predictions file against ground truth under the official protocol."""

from __future__ import annotations

import argparse
import sys

from zendar_dataset.cli.arguments import positive_number, whole_number
from zendar_dataset.cli.common import run_cli, writing
from zendar_dataset.cli.interrupt import console_script


def build_parser() -> argparse.ArgumentParser:
    # Imported here, not at the top, so that the console script's Ctrl-C handler is in place
    # before the evaluator's imports (numpy, numba).
    from zendar_dataset.eval.protocol import BANDS_M, DEFAULT_MAX_BYTES, MAX_BOOTSTRAP_RESAMPLES, MATCH_DISTANCE_M

    parser = argparse.ArgumentParser(
        prog="zendar-eval",
        description=(
            f"Score moving-car detections: center distance < {MATCH_DISTANCE_M:g} m, AP per range band "
            f"({', '.join(f'{band} [{low_m:g}, {high_m:g}) m' for band, (low_m, high_m) in BANDS_M.items())}). "
            "Every problem in the input is listed at once; exit status 2 when there are any."
        ),
    )
    parser.add_argument("predictions", help="predictions JSON: {\"meta\": {...}, \"results\": {frame_id: [...]}}")
    parser.add_argument(
        "--gt",
        required=True,
        help="dataset root (labels of --split) or ground-truth JSON file {\"frames\": {...}}",
    )
    parser.add_argument(
        "--split", default=None, help="split of a dataset root (default: test when labelled, else val)"
    )
    parser.add_argument(
        "--out",
        default=None,
        help="directory for metrics.json (and plots; problems.txt when the input has problems); created if "
        "missing; never inside the --gt dataset",
    )
    parser.add_argument("--plot", action="store_true", help="write PR curves per band as PNG into --out")
    parser.add_argument(
        "--bootstrap",
        type=whole_number("--bootstrap", 0, MAX_BOOTSTRAP_RESAMPLES),
        default=0,
        metavar="N",
        help=f"95%% confidence intervals from N scene resamples (at most {MAX_BOOTSTRAP_RESAMPLES:,})",
    )
    parser.add_argument(
        "--bootstrap-block-s",
        type=positive_number("--bootstrap-block-s"),
        default=None,
        metavar="S",
        help="resample each scene's consecutive frames in time blocks of S seconds instead of whole scenes",
    )
    parser.add_argument("--seed", type=whole_number("--seed", 0), default=0, help="seed (0 or more) for --bootstrap (default 0)")
    parser.add_argument(
        "--partial", action="store_true", help="evaluate only the frames present in the predictions"
    )
    parser.add_argument(
        "--max-bytes",
        type=whole_number("--max-bytes", 1),
        default=DEFAULT_MAX_BYTES,
        help=f"refuse input files larger than this (default {DEFAULT_MAX_BYTES:,})",
    )
    return parser


def _refuse_output_into_inputs(args: argparse.Namespace) -> None:
    """--out must not be inside a dataset given as --gt, nor make an input file one of its outputs."""
    import os

    from zendar_dataset.eval.report import OUTPUT_NAMES
    from zendar_dataset.output_location import refuse_output_inside

    gt_is_dataset = os.path.isdir(args.gt)
    refuse_output_inside(args.out, datasets=(args.gt,) if gt_is_dataset else (), what="--out")
    inputs = (args.predictions,) if gt_is_dataset else (args.predictions, args.gt)
    for name in OUTPUT_NAMES:
        refuse_output_inside(os.path.join(args.out, name), files=inputs, what="--out")


def _run(args: argparse.Namespace) -> int:
    # Imported here so that --help stays fast (numba, matplotlib).
    from zendar_dataset.errors import PredictionsError
    from zendar_dataset.eval.evaluate import evaluate_record
    from zendar_dataset.atomic_files import prepare_out_dir
    from zendar_dataset.eval.report import format_table, write_metrics, write_problems

    if args.out is not None:
        _refuse_output_into_inputs(args)
        with writing(args.out):
            prepare_out_dir(args.out)
    try:
        metrics = evaluate_record(
            args.predictions,
            args.gt,
            partial=args.partial,
            bootstrap=args.bootstrap,
            seed=args.seed,
            split=args.split,
            max_bytes=args.max_bytes,
            bootstrap_block_s=args.bootstrap_block_s,
        )
    except PredictionsError as exc:
        if args.out is not None:
            with writing(args.out):
                exc.problems_file = str(write_problems(exc.problems, args.out))
        raise
    print(format_table(metrics))
    if args.out is not None:
        with writing(args.out):
            print(f"wrote {write_metrics(metrics, args.out)}")
            if args.plot:
                from zendar_dataset.eval.render import plot_pr_curves

                for path in plot_pr_curves(metrics, args.out):
                    print(f"wrote {path}")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.plot and args.out is None:
        parser.error("--plot needs --out DIR to write the PNG files into")
    return run_cli(lambda: _run(args))


@console_script
def zendar_eval() -> int:
    """Console script ``zendar-eval``: Ctrl-C exits 130 from the start, imports included."""
    return main()


if __name__ == "__main__":
    sys.exit(zendar_eval())
