"""The scorer process: ``python -m zendar_leaderboard.worker --gt GT --db DB ...``.

It runs apart from the server so that a submission that is slow or large cannot stall the pages:
its address space is capped with ``resource.setrlimit(RLIMIT_AS)``, the server's watchdog kills it
at the time limit, and it dies with the server (``PR_SET_PDEATHSIG``). It loads the hidden labels
once, then reads one request per line on stdin, ``{"id": N}``, reads that submission's bytes from
the database (read-only: only the server writes), and answers one line on its stdout,
``{"id": N, "ok": true, "sha256": ..., "scores": {...}}`` or ``{"id": N, "ok": false, "error": ...}``,
with ``"store_error": true`` when the database could not be read (the server's fault: it asks again
later, and never charges the team for it). Error texts are fixed sentences meant for the submitting
team; details go to stderr (the server's log).
"""

from __future__ import annotations

import argparse
import ctypes
import os
import resource
import signal
import sqlite3
import sys
import traceback

import orjson

from zendar_leaderboard.ground_truth import load_test_split
from zendar_leaderboard.scoring import score_submission
from zendar_leaderboard.store import Store
from zendar_leaderboard.submission import check_submission

READY = "ready"


def _die_with_parent() -> None:
    # Linux: the kernel sends SIGKILL when the server process ends, even when it is killed itself.
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        PR_SET_PDEATHSIG = 1
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    except OSError:
        pass


def _limit_memory(memory_mb: int) -> None:
    limit = memory_mb * 1024 * 1024
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m zendar_leaderboard.worker")
    parser.add_argument("--gt", required=True)
    parser.add_argument("--split", default=None)
    parser.add_argument("--db", required=True)
    parser.add_argument("--bootstrap", type=int, default=0)
    parser.add_argument("--memory-mb", type=int, required=True)
    args = parser.parse_args(argv)
    _die_with_parent()
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the server, which stops this process
    # Answers go to the real stdout; anything a library prints goes to stderr instead.
    answers = os.fdopen(os.dup(1), "wb", buffering=0)
    os.dup2(2, 1)
    test_split = load_test_split(args.gt, args.split)
    store = Store(args.db, read_only=True)
    # Compile the evaluator's kernels before the limit and before the first submission.
    warm = {"meta": {}, "results": {f: [] for f in test_split.frames}}
    score_submission(warm, test_split, bootstrap=min(args.bootstrap, 10))
    _limit_memory(args.memory_mb)
    answers.write(orjson.dumps({READY: True, "gt_sha256": test_split.sha256}) + b"\n")
    for line in sys.stdin.buffer:
        submission_id = orjson.loads(line)["id"]
        answer: dict = {"id": submission_id, "ok": False}
        try:
            body = store.body(submission_id)
            if body is None:
                answer["error"] = "the submission was deleted before it was scored"
            else:
                checked = check_submission(body, list(test_split.frames))
                if not checked.ok:
                    answer["error"] = f"the submission no longer passes validation ({len(checked.problems)} problems)"
                else:
                    scores = score_submission(checked.document, test_split, bootstrap=args.bootstrap)
                    answer = {"id": submission_id, "ok": True, "sha256": checked.sha256, "scores": scores}
                del checked
        except sqlite3.Error as exc:
            print(f"submission {submission_id}: cannot read it from the database: {exc}", file=sys.stderr)
            answer.update(error="the database could not be read", store_error=True)
        except MemoryError:
            answer["error"] = f"scoring needed more than the memory limit of {args.memory_mb} MB"
        except Exception:  # any other failure is ours, not the team's: log it, answer plainly
            traceback.print_exc(file=sys.stderr)
            answer["error"] = "the scorer failed on this submission"
        answers.write(orjson.dumps(answer) + b"\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
