"""Scoring off the request path: scorer processes fed from the queue, with a watchdog.

Each slot owns one scorer process (``zendar_leaderboard.worker``) and scores one submission at a
time. The watchdog is the slot's deadline: a submission not answered within ``time_limit_s`` has its
scorer killed and is marked failed, and the slot starts a fresh scorer; a scorer that dies marks its
submission failed the same way. So every claimed submission reaches ``scored`` or ``failed`` within
``time_limit_s`` (plus a scorer start), and the queue drains at that pace at worst.

The database may refuse a write for a while (another connection holding the write lock past the
busy timeout, a full disk). A slot never ends on that: it logs the error and tries again with
doubling waits; a submission whose result cannot be recorded after ``STORE_ATTEMPTS`` is marked
failed as the server's fault, and does not count against its team's quota.
"""

from __future__ import annotations

import logging
import os
import queue
import sqlite3
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import orjson

from zendar_leaderboard.store import INFRASTRUCTURE_FAILURE, NOT_CHARGED, Store

log = logging.getLogger("zendar_leaderboard")

#: Seconds a fresh scorer may take to load the labels and compile the evaluator.
STARTUP_LIMIT_S = 300.0
#: Attempts at recording a submission's result (or at the scorer's reading of it) before giving up.
STORE_ATTEMPTS = 5
#: The wait after a first failed database step; each further failure doubles it, up to the maximum.
STORE_RETRY_WAIT_S = 1.0
STORE_RETRY_MAX_WAIT_S = 60.0
#: Why a submission failed when the score computed was not of its bytes (its row was changed meanwhile).
OTHER_BYTES_FAILURE = f"the bytes scored were not this submission's; {NOT_CHARGED}"


def retry_wait_s(failures: int) -> float:
    """The wait after ``failures`` consecutive failed database steps (1, 2, 4, ... times the first)."""
    return min(STORE_RETRY_WAIT_S * 2 ** (failures - 1), STORE_RETRY_MAX_WAIT_S)


@dataclass(frozen=True)
class ScorerSettings:
    """How submissions are scored.

    Attributes
    ----------
    gt, split
        The hidden labels, as given to ``serve``.
    db
        The database file.
    gt_sha256
        Checksum the scorer's labels must have (the server's own copy).
    time_limit_s
        Wall-clock limit per submission.
    memory_mb
        Address-space limit of a scorer process.
    bootstrap
        Scene resamples for the intervals.
    workers
        Scorer processes (each scores one submission at a time).
    """

    gt: str
    split: str | None
    db: str
    gt_sha256: str
    time_limit_s: float = 600.0
    memory_mb: int = 4096
    bootstrap: int = 200
    workers: int = 1


class ScorerFailed(Exception):
    """The scorer process could not be started or stopped answering."""


class _Scorer:
    """One scorer process and a thread that reads its answers into a queue."""

    def __init__(self, settings: ScorerSettings) -> None:
        command = [
            sys.executable, "-m", "zendar_leaderboard.worker", "--gt", settings.gt, "--db", settings.db,
            "--bootstrap", str(settings.bootstrap), "--memory-mb", str(settings.memory_mb),
        ]
        if settings.split is not None:
            command += ["--split", settings.split]
        # One thread each: scoring is single-threaded and the machine is shared with the server.
        env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1", NUMBA_NUM_THREADS="1")
        self.process = subprocess.Popen(
            command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env, cwd=Path(settings.db).parent
        )
        self.answers: queue.Queue = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()
        try:
            ready = self.answer(STARTUP_LIMIT_S)
            if not ready.get("ready"):
                raise ScorerFailed("the scorer did not start")
            if ready.get("gt_sha256") != settings.gt_sha256:
                raise ScorerFailed("the scorer read other labels than the server (the ground truth changed on disk)")
        except BaseException:
            self.kill()  # slow to start or wrong: never leave it running beside its replacement
            raise

    def _read(self) -> None:
        try:
            for line in self.process.stdout:
                self.answers.put(orjson.loads(line))
        except orjson.JSONDecodeError:
            pass  # a line cut short by the scorer's death: the end of its output
        finally:
            self.answers.put(None)  # end of output: the process died

    def answer(self, timeout_s: float) -> dict:
        try:
            answer = self.answers.get(timeout=timeout_s)
        except queue.Empty:
            raise TimeoutError from None
        if answer is None:
            raise ScorerFailed(f"the scorer stopped (exit status {self.process.wait()})")
        return answer

    def ask(self, submission_id: int) -> None:
        self.process.stdin.write(orjson.dumps({"id": submission_id}) + b"\n")
        self.process.stdin.flush()

    def kill(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
        self.process.wait()


class ScoringService:
    """Scores queued submissions in the background until :meth:`stop`.

    Parameters
    ----------
    store
        The database (shared with the server).
    settings
        Scorer settings.
    """

    def __init__(self, store: Store, settings: ScorerSettings) -> None:
        self.store = store
        self.settings = settings
        self._wake = threading.Event()
        self._stopping = threading.Event()
        self._threads = [
            threading.Thread(target=self._slot, name=f"scorer-{k}", daemon=True) for k in range(settings.workers)
        ]
        self._scorers: list[_Scorer] = []
        self._lock = threading.Lock()

    def start(self) -> None:
        for thread in self._threads:
            thread.start()

    def wake(self) -> None:
        """Tell the slots that a submission was queued."""
        self._wake.set()

    def stop(self) -> None:
        """Stop scoring; a submission being scored goes back to the queue."""
        self._stopping.set()
        self._wake.set()
        with self._lock:
            for scorer in self._scorers:
                scorer.kill()
        for thread in self._threads:
            thread.join(timeout=10)

    def _new_scorer(self) -> _Scorer | None:
        try:
            scorer = _Scorer(self.settings)
        except (ScorerFailed, TimeoutError, OSError) as exc:
            log.error("could not start a scorer: %s", exc)
            return None
        with self._lock:
            self._scorers.append(scorer)
        return scorer

    def _drop(self, scorer: _Scorer) -> None:
        scorer.kill()
        with self._lock:
            if scorer in self._scorers:  # an unexpected error may follow a drop
                self._scorers.remove(scorer)

    def _slot(self) -> None:
        scorer: _Scorer | None = None
        failures = 0
        while not self._stopping.is_set():
            try:
                if scorer is None:
                    scorer = self._new_scorer()
                    if scorer is None:
                        self._stopping.wait(5.0)
                        continue
                scorer = self._step(scorer)
                failures = 0
            except Exception as exc:  # the slot outlives any error: it logs it and keeps going
                if scorer is not None and scorer.process.poll() is not None:
                    self._drop(scorer)
                    scorer = None  # else the slot keeps its scorer (a failed claim leaves it idle)
                failures += 1
                wait_s = retry_wait_s(failures)
                if isinstance(exc, sqlite3.Error):
                    log.error("scoring: the queue cannot be read or claimed (%s); trying again in %g s", exc, wait_s)
                else:
                    log.exception("scoring: unexpected error; trying again in %g s", wait_s)
                self._stopping.wait(wait_s)
        if scorer is not None:
            self._drop(scorer)

    def _step(self, scorer: _Scorer) -> _Scorer | None:
        """Claim and score one submission (or wait for one); returns the scorer unless it was dropped."""
        submission_id = self.store.claim_next()
        if submission_id is None:
            self._wake.wait(1.0)
            self._wake.clear()
            return scorer
        try:
            return self._score(scorer, submission_id)
        except Exception:
            log.exception("submission %d: unexpected error while scoring", submission_id)
            self._drop(scorer)
            self._settle(submission_id, None)
            return None

    def _score(self, scorer: _Scorer, submission_id: int) -> _Scorer | None:
        """Score a claimed submission and record the outcome; returns the scorer unless it was dropped."""
        started = time.monotonic()
        for attempt in range(1, STORE_ATTEMPTS + 1):
            try:
                scorer.ask(submission_id)
                answer = scorer.answer(self.settings.time_limit_s)
            except TimeoutError:
                self._drop(scorer)
                log.warning("submission %d: time limit, scorer killed", submission_id)
                self._settle(submission_id, lambda: self.store.record_failure(
                    submission_id, f"scoring took longer than the limit of {self.settings.time_limit_s:g} s"
                ))
                return None
            except (ScorerFailed, OSError) as exc:
                self._drop(scorer)
                if self._stopping.is_set():
                    self._release(submission_id)
                else:
                    log.warning("submission %d: %s", submission_id, exc)
                    self._settle(submission_id, lambda: self.store.record_failure(
                        submission_id,
                        f"the scorer stopped while scoring this submission (memory limit {self.settings.memory_mb} MB)",
                    ))
                return None
            if not answer.get("store_error"):
                break
            log.warning("submission %d: the scorer could not read it (%d of %d)", submission_id, attempt,
                        STORE_ATTEMPTS)
            if attempt == STORE_ATTEMPTS:
                self._settle(submission_id, None)
                return scorer
            if self._stopping.wait(retry_wait_s(attempt)):
                self._release(submission_id)
                return scorer
        if answer.get("ok"):
            self._settle(submission_id, lambda: self._record_score(submission_id, answer))
            log.info("submission %d scored in %.1f s", submission_id, time.monotonic() - started)
        else:
            self._settle(submission_id, lambda: self.store.record_failure(submission_id, answer["error"]))
            log.info("submission %d failed: %s", submission_id, answer["error"])
        return scorer

    def _record_score(self, submission_id: int, answer: dict) -> None:
        if not self.store.record_score(submission_id, answer["sha256"], answer["scores"]):
            # Deleted meanwhile (then this changes nothing), or holding other bytes than those scored.
            log.warning("submission %d: score not recorded (deleted, or other bytes)", submission_id)
            self.store.record_failure(submission_id, OTHER_BYTES_FAILURE, counts_for_quota=False)

    def _release(self, submission_id: int) -> None:
        """Put a submission back in the queue as the server stops (one try: else the next start does)."""
        self._retried(lambda: self.store.release(submission_id), f"submission {submission_id}", 1)

    def _settle(self, submission_id: int, write: Callable[[], object] | None) -> None:
        """End a claimed submission's scoring with ``write``, retried with doubling waits.

        When ``write`` keeps failing (or is None: the failure is already known to be the server's),
        the submission is marked failed without counting against its team's quota, retried until
        that is recorded; a server stopping meanwhile leaves it in ``scoring``, and the next start
        queues it again.
        """
        what = f"submission {submission_id}"
        if write is not None and self._retried(write, what, STORE_ATTEMPTS) or self._stopping.is_set():
            return
        self._retried(
            lambda: self.store.record_failure(submission_id, INFRASTRUCTURE_FAILURE, counts_for_quota=False), what, None
        )

    def _retried(self, write: Callable[[], object], what: str, attempts: int | None) -> bool:
        """Run ``write`` until it succeeds (True), ``attempts`` fail (None: no limit) or the server stops."""
        failures = 0
        while True:
            try:
                write()
                return True
            except sqlite3.Error as exc:
                failures += 1
                if attempts is not None and failures >= attempts:
                    log.error("%s: the database refused the result %d times (%s); giving up", what, failures, exc)
                    return False
                wait_s = retry_wait_s(failures)
                log.error("%s: the database refused the result (%s); trying again in %g s", what, exc, wait_s)
                if self._stopping.wait(wait_s):
                    return False
