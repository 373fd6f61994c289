"""``zendar-eval``: score a predictions file against ground truth under the official protocol."""

from __future__ import annotations

from zendar_dataset.cli.interrupt import exit_while_starting

if __name__ == "__main__":  # python -m: Ctrl-C during the imports below exits 130 quietly
    exit_while_starting()

import argparse
import sys

from zendar_dataset.cli.common import run_cli
from zendar_dataset.eval.protocol import DEFAULT_MAX_BYTES


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="zendar-eval",
        description=(
            "Score moving-car detections: center distance < 2.5 m, AP per range band "
            "(near [0, 15) m, mid [15, 30) m, far [30, 60) m, all [0, 60) m). "
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
    parser.add_argument("--out", default=None, help="directory for metrics.json (and plots); created if missing")
    parser.add_argument("--plot", action="store_true", help="write PR curves per band as PNG into --out")
    parser.add_argument(
        "--bootstrap", type=int, default=0, metavar="N", help="95%% confidence intervals from N scene resamples"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed for --bootstrap (default 0)")
    parser.add_argument(
        "--partial", action="store_true", help="evaluate only the frames present in the predictions"
    )
    parser.add_argument(
        "--max-bytes",
        type=int,
        default=DEFAULT_MAX_BYTES,
        help=f"refuse input files larger than this (default {DEFAULT_MAX_BYTES:,})",
    )
    return parser


def _run(args: argparse.Namespace) -> int:
    # Imported here so that --help stays fast (numba, matplotlib).
    from zendar_dataset.eval.evaluate import evaluate
    from zendar_dataset.eval.report import format_table, write_metrics

    metrics = evaluate(
        args.predictions,
        args.gt,
        partial=args.partial,
        bootstrap=args.bootstrap,
        seed=args.seed,
        split=args.split,
        max_bytes=args.max_bytes,
    )
    print(format_table(metrics))
    if args.out is not None:
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
    if args.bootstrap < 0:
        parser.error("--bootstrap must be 0 or more")
    if args.max_bytes <= 0:
        parser.error("--max-bytes must be positive")
    return run_cli(lambda: _run(args))


if __name__ == "__main__":
    sys.exit(main())
