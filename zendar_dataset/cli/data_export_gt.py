"""``zendar-data export-gt ROOT --split S -o gt.json``: ground truth for ``zendar-eval --gt``."""

from __future__ import annotations

import argparse

from zendar_dataset.cli.common import EXIT_OK, writing


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "export-gt",
        help="write a split's moving-car labels as the evaluator's ground-truth JSON",
        description='Write {"frames": {"<scene_id>/<timestamp_ns>": [car, ...]}} for every SAR frame of the '
        "labelled scenes of a split (frames without cars have an empty list).",
    )
    parser.add_argument("root", metavar="ROOT", help="dataset root (directory or fsspec URL)")
    parser.add_argument("--split", required=True, help="split to export (train, val, ...)")
    parser.add_argument("-o", "--output", required=True, help="JSON file to write (must not exist unless --overwrite; never inside ROOT)")
    parser.add_argument("--overwrite", action="store_true", help="replace OUTPUT if it exists")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from zendar_dataset.errors import ZendarError
    from zendar_dataset.format.ground_truth import export_ground_truth

    try:
        with writing(args.output):
            n_frames = export_ground_truth(args.root, args.split, args.output, overwrite=args.overwrite)
    except FileExistsError:
        raise ZendarError(f"{args.output} exists already (pass --overwrite to replace it)") from None
    print(f"wrote {args.output}: {n_frames} frames of split {args.split!r}")
    return EXIT_OK
