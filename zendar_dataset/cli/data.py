"""``zendar-data``: inspect, validate, convert, export ground truth, synthesise.

Each subcommand lives in its own module exposing ``register(subparsers)``,
which adds its parser and sets ``func`` to a callable taking the parsed
arguments and returning an exit status.
"""

from __future__ import annotations

from zendar_dataset.cli.interrupt import exit_while_starting

if __name__ == "__main__":  # python -m: Ctrl-C during the imports below exits 130 quietly
    exit_while_starting()

import argparse
import sys

from zendar_dataset.cli import (
    data_convert,
    data_export_gt,
    data_fidelity,
    data_import_release,
    data_info,
    data_synth,
    data_validate,
)
from zendar_dataset.cli.common import run_cli

SUBCOMMANDS = (data_info, data_validate, data_convert, data_export_gt, data_synth, data_import_release, data_fidelity)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="zendar-data",
        description="Inspect, validate, convert and synthesise Zendar format-v1 datasets.",
    )
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in SUBCOMMANDS:
        module.register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    return run_cli(lambda: args.func(args))


if __name__ == "__main__":
    sys.exit(main())
