"""``zendar-data convert ROOT OUT --to zarr|hdf5``: lossless backend conversion."""

from __future__ import annotations

import argparse

from zendar_dataset.cli.common import EXIT_OK, writing


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "convert",
        help="copy a dataset into the other backend, losslessly",
        description="Copy every scene of ROOT into a new dataset OUT stored as zarr v3 or HDF5. "
        "Arrays are bit-identical and attributes equal; OUT must not exist or be empty, and must not be "
        "inside ROOT.",
    )
    parser.add_argument("root", metavar="ROOT", help="source dataset root (directory or fsspec URL)")
    parser.add_argument("out", metavar="OUT", help="new dataset root to create")
    parser.add_argument("--to", required=True, choices=("zarr", "hdf5"), help="backend of OUT")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from zendar_dataset.errors import ZendarError
    from zendar_dataset.format.convert import convert_dataset

    try:
        with writing(args.out):
            out = convert_dataset(args.root, args.out, to=args.to)
    except FileExistsError as exc:
        raise ZendarError(str(exc)) from None
    print(f"wrote {out} ({args.to})")
    return EXIT_OK
