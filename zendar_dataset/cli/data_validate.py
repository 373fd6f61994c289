"""``zendar-data validate ROOT``: list every format-v1 violation, exit 2 when any."""

from __future__ import annotations

import argparse
import sys

from zendar_dataset.cli.common import EXIT_OK, EXIT_USAGE


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "validate",
        help="check a dataset against format v1 (docs/format.md), reporting every violation",
        description="Check dataset.json and every scene (attributes, arrays, every chunk) against format v1. "
        "Prints every violation and exits 2 when there is any. Reads only.",
    )
    parser.add_argument("root", metavar="ROOT", help="dataset root (directory or fsspec URL)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from zendar_dataset.format.reader import open_dataset
    from zendar_dataset.format.validate import validate_dataset

    notes: list[str] = []
    problems = validate_dataset(args.root, notes=notes)
    for note in notes:
        print(note)
    if problems:
        for problem in problems:
            print(problem)
        print(f"{args.root}: {len(problems)} format violation(s)", file=sys.stderr)
        return EXIT_USAGE
    index = open_dataset(args.root)
    splits = ", ".join(f"{name}={len(ids)}" for name, ids in index.splits.items())
    print(f"ok: {args.root}: {len(index.scenes)} scenes ({splits}) conform to format v1")
    return EXIT_OK
