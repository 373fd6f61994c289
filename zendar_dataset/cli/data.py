"""``zendar-data``: inspect, validate, convert, export ground truth, synthesise.

Each subcommand lives in its own module exposing ``register(subparsers)``,
which adds its parser and sets ``func`` to a callable taking the parsed
arguments and returning an exit status.
"""

from __future__ import annotations

import argparse
import sys

from zendar_dataset.cli.common import run_cli
from zendar_dataset.cli.interrupt import console_script


def build_parser() -> argparse.ArgumentParser:
    # The subcommands are imported here, not at the top, so that the console script's Ctrl-C
    # handler is in place before their imports (zarr, numba).
    from zendar_dataset.cli import (
        data_convert,
        data_export_gt,
        data_fidelity,
        data_import_release,
        data_info,
        data_synth,
        data_validate,
    )

    parser = argparse.ArgumentParser(
        prog="zendar-data",
        description="Inspect, validate, convert and synthesise Zendar format-v1 datasets.",
    )
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in (data_info, data_validate, data_convert, data_export_gt, data_synth, data_import_release, data_fidelity):
        module.register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    return run_cli(lambda: args.func(args))


@console_script
def zendar_data() -> int:
    """Console script ``zendar-data``: Ctrl-C exits 130 from the start, imports included."""
    return main()


if __name__ == "__main__":
    sys.exit(zendar_data())
