"""``zendar-data import-release SRC OUT``: convert the original release's ``.pbs`` streams to format v1."""

from __future__ import annotations

import argparse
import errno
import sys

from zendar_dataset.cli.common import EXIT_FAILURE, EXIT_USAGE
from zendar_dataset.errors import ZendarError
from zendar_dataset.format.schema import SPLITS

# OS errors that are the environment's fault (disk full, read-only, no permission): exit 1, not 2.
_ENVIRONMENT_ERRNOS = {errno.ENOSPC, errno.EROFS, errno.EACCES, errno.EPERM, errno.EDQUOT, errno.EIO}


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "import-release",
        help="convert the original 2020 release (.pbs protobuf streams) to format v1",
        description="Read every stream of a Zendar release folder (one scene, or a tree of "
        "<date>_<time>/<NNN> scenes), detect framing, message kind and schema generation, and write one "
        "format-v1 scene per release scene. SRC is never modified; scenes are written atomically; "
        "re-running into the same OUT resumes. Prints what was read, skipped and assumed.",
    )
    parser.add_argument("src", metavar="SRC", help="release folder, or one stream file")
    parser.add_argument("out", metavar="OUT", help="dataset root to create or resume")
    parser.add_argument("--scene-id", default=None, metavar="ID", help="scene id (only when SRC holds one scene)")
    parser.add_argument(
        "--split", default="train", metavar="S", help=f"split of the imported scenes (default: train; usual: {', '.join(SPLITS)})"
    )
    parser.add_argument("--skip-corrupt", action="store_true",
                        help="skip truncated or corrupt stretches of streams (reported) instead of stopping")
    parser.add_argument("--backend", choices=("zarr", "hdf5"), default="zarr", help="scene store format (default: zarr)")
    parser.add_argument(
        "--sides", type=_stated_sides, default=None, metavar="SERIAL=left,SERIAL=right",
        help="which radar serial is on which side, when known: taken instead of deciding it from the images' "
        "attitude and the path driven (needed when those disagree); in a scene where it names some radars, "
        "the others keep their serials",
    )
    parser.set_defaults(func=_run)


def _stated_sides(text: str) -> dict[str, str]:
    from zendar_dataset.release.sides import parse_stated_sides

    try:
        return parse_stated_sides(text)
    except ZendarError as exc:
        # Raised as an ArgumentError without an argument, argparse prints the message alone (exit 2).
        raise argparse.ArgumentError(None, str(exc)) from None


def _run(args: argparse.Namespace) -> int:
    from zendar_dataset.release import import_release

    try:
        summary = import_release(
            args.src,
            args.out,
            scene_id=args.scene_id,
            split=args.split,
            skip_corrupt=args.skip_corrupt,
            backend=args.backend,
            sides=args.sides,
            log=lambda scene_id: print(f"importing {scene_id} ...", file=sys.stderr),
        )
    except FileNotFoundError:
        raise  # a path the user gave: exit 2 through run_cli
    except OSError as exc:
        print(f"error: {exc.filename or args.out}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_FAILURE if exc.errno in _ENVIRONMENT_ERRNOS else EXIT_USAGE
    print("\n".join(summary.lines()))
    return 0
