"""``zendar-leaderboard``: check, serve, add-team, submit, render, and the administrator's commands.

Problems in a user's file or arguments exit 2 without a traceback; an environment failure (a port
in use, a full disk, a server that cannot be reached) exits 1 naming the path or address and the OS
error; Ctrl-C exits 130.
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sqlite3
import sys
from pathlib import Path

from zendar_dataset.cli.arguments import positive_number, whole_number
from zendar_dataset.cli.common import run_cli
from zendar_dataset.cli.interrupt import console_script
from zendar_dataset.errors import ZendarError

EXIT_ENVIRONMENT = 1
# Bounds the OS can honour: a timeout near 1e308 s overflows (the scheduler's queue and the socket
# timeouts), and a week is longer than any wait helps; the address-space limit is a C long of bytes.
MAX_WAIT_S = 7 * 24 * 3600
MAX_MEMORY_MB = 8 * 2**20  # 8 TiB


def _existing_store(db: str):
    from zendar_leaderboard.store import Store

    if not Path(db).is_file():
        raise ZendarError(f"no leaderboard database at {db!r} (create one with add-team)")
    return Store(db, existing=True)  # an empty or foreign file is refused, not given the tables


def _check(args: argparse.Namespace) -> int:
    from zendar_leaderboard.ground_truth import load_test_split
    from zendar_leaderboard.submission import check_submission

    path = Path(args.file)
    if not path.is_file():
        raise ZendarError(f"submission file {args.file!r} does not exist or is not a file")
    size = path.stat().st_size
    if size > args.max_bytes:
        raise ZendarError(f"submission file {args.file!r} is {size:,} bytes, over the limit of {args.max_bytes:,} bytes")
    frame_ids = None
    if args.gt is not None:
        frame_ids = list(load_test_split(args.gt, args.split).frames)
    checked = check_submission(path.read_bytes(), frame_ids)
    if not checked.ok:
        raise _problems(args.file, checked.problems)
    n_frames = len(checked.document["results"])
    n_detections = sum(map(len, checked.document["results"].values()))
    print(f"{args.file}: valid ({n_frames} frames, {n_detections} detections, method {checked.meta['method']!r})")
    if frame_ids is None:
        print("frames were not compared with the test split (give --gt to compare them)")
    return 0


def _problems(name: str, problems: list[str]) -> ZendarError:
    return ZendarError(f"{len(problems)} problems in {name!r}", problems)


def _serve(args: argparse.Namespace) -> int:
    from zendar_leaderboard.store import lock_for_serving

    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(asctime)s %(message)s")
    db = Path(args.db)
    if not db.parent.is_dir():
        raise ZendarError(f"the folder of --db {args.db!r} does not exist")
    # Before anything else: a second server on the database would put the first one's submission in
    # progress back in the queue (exit 2 here, nothing touched).
    with lock_for_serving(db):
        return _serve_locked(args, db)


def _serve_locked(args: argparse.Namespace, db: Path) -> int:
    from zendar_dataset.eval.protocol import PROTOCOL_VERSION
    from zendar_leaderboard.ground_truth import load_test_split
    from zendar_leaderboard.scheduler import ScorerSettings, ScoringService
    from zendar_leaderboard.server import LeaderboardHTTPServer, ServerSettings
    from zendar_leaderboard.store import Store

    test_split = load_test_split(args.gt, args.split)
    store = Store(db)
    scoring = ScoringService(store, ScorerSettings(
        gt=str(Path(args.gt).resolve()), split=test_split.split, db=str(db.resolve()), gt_sha256=test_split.sha256,
        time_limit_s=args.time_limit_s, memory_mb=args.memory_mb, bootstrap=args.bootstrap, workers=args.workers,
    ))
    settings = ServerSettings(
        store, test_split, scoring, quota=args.quota, max_bytes=args.max_bytes, upload_deadline_s=args.upload_deadline_s,
        max_connections=args.max_connections, max_connections_per_address=args.max_connections_per_address,
    )
    try:
        server = LeaderboardHTTPServer((args.host, args.port), settings)
    except OSError as exc:
        print(f"error: cannot listen on {args.host}:{args.port}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_ENVIRONMENT
    # Only a server that got its port takes over the queue.
    recovered = store.recover(PROTOCOL_VERSION, test_split.sha256)
    scoring.start()
    host, port = server.server_address[:2]
    print(
        f"serving http://{host}:{port}/ - split {test_split.split or '(file)'}: {len(test_split.frames)} frames, "
        f"public {len(test_split.public_frame_ids)}, private {len(test_split.private_frame_ids)}; "
        f"labels sha256 {test_split.sha256[:12]}...; requeued {recovered['requeued']}, "
        f"re-scoring {recovered['rescore']}",
        flush=True,
    )
    # SIGTERM stops the server like Ctrl-C: the submission being scored goes back to the queue.
    signal.signal(signal.SIGTERM, lambda *_: (_ for _ in ()).throw(KeyboardInterrupt))
    try:
        server.serve_forever()
    finally:
        scoring.stop()
        server.server_close()
    return 0


def _add_team(args: argparse.Namespace) -> int:
    from zendar_leaderboard.names import normalised
    from zendar_leaderboard.store import Store

    if not Path(args.db).parent.is_dir():
        raise ZendarError(f"the folder of --db {args.db!r} does not exist")
    token = Store(args.db).add_team(args.name)
    print(token)
    print(f"team {normalised(args.name)!r} registered; its token is shown only this once", file=sys.stderr)
    return 0


#: The environment variable ``submit`` reads the team's token from.
TOKEN_VARIABLE = "ZENDAR_LEADERBOARD_TOKEN"


def _submit_token(args: argparse.Namespace) -> str:
    """The team's token: from --token-file, --token (with a warning) or the environment."""
    if args.token_file is not None:
        path = Path(args.token_file)
        try:
            token = path.read_text(encoding="utf-8").strip()
        except (OSError, UnicodeDecodeError) as exc:
            raise ZendarError(f"cannot read the token file {args.token_file!r}: {getattr(exc, 'strerror', None) or exc}") from None
        if not token:
            raise ZendarError(f"the token file {args.token_file!r} is empty")
        return token
    if args.token is not None:
        print(f"warning: --token is visible to every user of this machine (ps); "
              f"prefer --token-file PATH or {TOKEN_VARIABLE}", file=sys.stderr)
        return args.token
    token = os.environ.get(TOKEN_VARIABLE, "").strip()
    if not token:
        raise ZendarError(f"no token: give --token-file PATH (a file holding the team's token) or set {TOKEN_VARIABLE}")
    return token


def _server_url(text: str) -> str:
    """``type=`` of ``submit --server``: a URL that cannot name a server is refused before anything is sent."""
    from zendar_leaderboard.client import check_server_url

    try:
        return check_server_url(text)
    except ValueError as exc:
        # Printed as "PROG: error: MESSAGE", like the shared checks of command-line values.
        raise argparse.ArgumentError(None, f"invalid --server URL {text!r}: {exc}") from None


def _submit(args: argparse.Namespace) -> int:
    from zendar_leaderboard.client import ServerUnreachable, submit

    token = _submit_token(args)
    try:
        return submit(args.file, args.server, token, wait=not args.no_wait, timeout_s=args.timeout_s)
    except ServerUnreachable as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_ENVIRONMENT


def _render(args: argparse.Namespace) -> int:
    from zendar_leaderboard.export import render_site

    written = render_site(_existing_store(args.db), args.out)
    print(f"wrote {len(written)} files to {args.out} (open {Path(args.out) / 'index.html'})")
    return 0


def _admin(args: argparse.Namespace) -> int:
    store = _existing_store(args.db)
    if args.command == "close-round":
        store.close_round()
        print("round closed: the ranking now shows the private part; new submissions are refused")
    elif args.command == "hide":
        store.set_hidden(args.id, True)
        print(f"submission {args.id} hidden from the ranking")
    elif args.command == "unhide":
        store.set_hidden(args.id, False)
        print(f"submission {args.id} shown on the ranking again")
    elif args.command == "delete":
        store.delete(args.id)
        print(f"submission {args.id} deleted with its score")
    elif args.command == "list":
        print(f"{'id':>5}  {'team':<20} {'method':<40} {'status':<8} hidden  error")
        for row in store.submissions():
            print(f"{row.id:>5}  {row.team[:20]:<20} {row.meta.get('method', '')[:40]:<40} {row.status:<8} "
                  f"{'yes' if row.hidden else 'no':<7} {row.error or ''}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    from zendar_dataset.eval.protocol import MAX_BOOTSTRAP_RESAMPLES
    from zendar_leaderboard.store import MAX_SUBMISSION_ID
    from zendar_leaderboard.submission import DEFAULT_MAX_BYTES

    max_bytes = whole_number("--max-bytes", 1)
    parser = argparse.ArgumentParser(
        prog="zendar-leaderboard",
        description="Submissions scored by the official evaluator against a hidden test split (docs/leaderboard.md).",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("check", help="check a submission offline exactly as the server does")
    p.add_argument("file", metavar="FILE")
    p.add_argument("--gt", default=None, help="ground truth (file or dataset root) to compare frame ids with")
    p.add_argument("--split", default=None, help="split of a dataset root given as --gt")
    p.add_argument("--max-bytes", type=max_bytes, default=DEFAULT_MAX_BYTES, help=f"size limit (default {DEFAULT_MAX_BYTES:,})")
    p.set_defaults(func=_check)

    p = sub.add_parser("serve", help="run the leaderboard server")
    p.add_argument("--gt", required=True, help="ground truth: an export-gt file or a dataset root (with --split)")
    p.add_argument("--db", required=True, help="SQLite database (created if missing)")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=whole_number("--port", 0, 65_535), default=8000,
                   help="port (0: any free port, printed)")
    p.add_argument("--split", default=None, help="split of a dataset root (default: test when labelled, else val)")
    p.add_argument("--quota", type=whole_number("--quota", 1), default=3,
                   help="scored submissions per team per rolling 30 days (default 3)")
    p.add_argument("--max-bytes", type=max_bytes, default=DEFAULT_MAX_BYTES, help=f"largest upload (default {DEFAULT_MAX_BYTES:,})")
    p.add_argument("--upload-deadline-s", type=positive_number("--upload-deadline-s", MAX_WAIT_S), default=None,
                   help="time to send a whole upload (default: 10 s + --max-bytes at 250 kB/s)")
    p.add_argument("--max-connections", type=whole_number("--max-connections", 1), default=512,
                   help="open connections in all (default 512)")
    p.add_argument("--max-connections-per-address", type=whole_number("--max-connections-per-address", 1), default=64,
                   help="open connections per client address (default 64)")
    p.add_argument("--time-limit-s", type=positive_number("--time-limit-s", MAX_WAIT_S), default=600.0,
                   help="scoring time per submission (default 600)")
    p.add_argument("--memory-mb", type=whole_number("--memory-mb", 1, MAX_MEMORY_MB), default=4096,
                   help="address-space limit of the scorer (default 4096)")
    p.add_argument("--bootstrap", type=whole_number("--bootstrap", 0, MAX_BOOTSTRAP_RESAMPLES), default=200,
                   help="scene resamples for the intervals (default 200)")
    p.add_argument("--workers", type=whole_number("--workers", 1), default=1, help="scorer processes (default 1)")
    p.add_argument("--verbose", action="store_true", help="log every request and score")
    p.set_defaults(func=_serve)

    p = sub.add_parser("add-team", help="register a team and print its token once")
    p.add_argument("name", metavar="NAME")
    p.add_argument("--db", required=True)
    p.set_defaults(func=_add_team)

    p = sub.add_parser("submit", help="upload a submission, wait for its score and print it")
    p.add_argument("file", metavar="FILE")
    p.add_argument("--server", type=_server_url, required=True,
                   help="the leaderboard's URL, e.g. http://127.0.0.1:8000")
    tokens = p.add_mutually_exclusive_group()
    tokens.add_argument("--token-file", default=None, metavar="PATH", help="a file holding the team's token")
    tokens.add_argument("--token", default=None,
                        help=f"the team's token (visible to other users of this machine; prefer --token-file or {TOKEN_VARIABLE})")
    p.add_argument("--no-wait", action="store_true", help="return once queued")
    p.add_argument("--timeout-s", type=positive_number("--timeout-s", MAX_WAIT_S), default=3600.0,
                   help="give up waiting after this long (default 3600)")
    p.set_defaults(func=_submit)

    p = sub.add_parser("render", help="write the static site: index.html, leaderboard.json, leaderboard.csv")
    p.add_argument("--db", required=True)
    p.add_argument("out", metavar="OUT")
    p.set_defaults(func=_render)

    for name, text in (("hide", "hide an entry from the ranking"), ("unhide", "show a hidden entry again"),
                       ("delete", "delete a submission and its score")):
        p = sub.add_parser(name, help=text)
        p.add_argument("id", type=whole_number("ID", 1, MAX_SUBMISSION_ID), metavar="ID")
        p.add_argument("--db", required=True)
        p.set_defaults(func=_admin)
    p = sub.add_parser("close-round", help="show the private part's scores and stop taking submissions")
    p.add_argument("--db", required=True)
    p.set_defaults(func=_admin)
    p = sub.add_parser("list", help="list every submission with its status")
    p.add_argument("--db", required=True)
    p.set_defaults(func=_admin)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)

    def body() -> int:
        try:
            return args.func(args)
        except OSError as exc:
            if isinstance(exc, FileNotFoundError):
                raise
            where = exc.filename or getattr(args, "db", None) or ""
            print(f"error: {where}: {exc.strerror or exc}", file=sys.stderr)
            return EXIT_ENVIRONMENT
        except sqlite3.Error as exc:  # a full disk, a read-only or corrupt database file
            print(f"error: database {getattr(args, 'db', '')}: {exc}", file=sys.stderr)
            return EXIT_ENVIRONMENT

    return run_cli(body)


@console_script
def zendar_leaderboard() -> int:
    """Console script ``zendar-leaderboard``: Ctrl-C exits 130 from the start, imports included."""
    return main()


if __name__ == "__main__":
    sys.exit(zendar_leaderboard())
