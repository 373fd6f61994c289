"""``zendar-data fidelity ROOT [--split S] [--out DIR]``: how well labels, radar and SAR agree."""

from __future__ import annotations

import argparse
import sys

from zendar_dataset.cli.common import EXIT_OK, writing

REPORT_JSON = "fidelity.json"


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "fidelity",
        help="measure labels, field of view, SAR coverage, CFAR and moving/static separation per range band",
        description="Per range band (near [0,15), mid [15,30), far [30,60) m): labels, the share of labels inside a "
        "radar's field of view, visible moving cars without a label (simulated datasets, from their truth), SAR "
        "coverage of labelled cars, CFAR detection rate, ROC AUC of the SAR mask and of the plain Doppler test at "
        "separating CFAR detections on moving cars from static ones, and the AP of the classical detector.",
    )
    parser.add_argument("root", metavar="ROOT", help="dataset root")
    parser.add_argument("--split", default=None, help="only this split's scenes (default: every scene)")
    parser.add_argument("--out", metavar="DIR", default=None,
                        help=f"also write DIR/{REPORT_JSON} (replaced if present); DIR must be outside ROOT")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import pathlib

    from zendar_dataset.atomic_files import write_json_atomic
    from zendar_dataset.fidelity import fidelity_report, format_report
    from zendar_dataset.output_location import refuse_output_inside

    if args.out is not None:
        # Checked before measuring, which takes minutes: no command writes into a dataset it reads.
        refuse_output_inside(args.out, datasets=(args.root,), what="--out")
    report = fidelity_report(args.root, args.split, progress=lambda scene: print(f"measuring {scene}", file=sys.stderr))
    print(format_report(report))
    if args.out is not None:
        out = pathlib.Path(args.out)
        with writing(out):
            out.mkdir(parents=True, exist_ok=True)
            write_json_atomic(out / REPORT_JSON, report)
        print(f"wrote {out / REPORT_JSON}")
    return EXIT_OK
