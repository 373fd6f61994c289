"""Scoring off the request path: scorer processes fed from the queue, with a watchdog.

Each slot owns one scorer process (``zendar_leaderboard.worker``) and scores one submission at a
time. The watchdog is the slot's deadline: a submission not answered within ``time_limit_s`` has its
scorer killed and is marked failed, and the slot starts a fresh scorer; a scorer that dies marks its
submission failed the same way. So every claimed submission reaches ``scored`` or ``failed`` within
``time_limit_s`` (plus a scorer start), and the queue drains at that pace at worst.
"""

from __future__ import annotations

import logging
import os
import queue
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import orjson

from zendar_leaderboard.store import Store

log = logging.getLogger("zendar_leaderboard")

#: Seconds a fresh scorer may take to load the labels and compile the evaluator.
STARTUP_LIMIT_S = 300.0


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
            self._scorers.remove(scorer)

    def _slot(self) -> None:
        scorer: _Scorer | None = None
        while not self._stopping.is_set():
            if scorer is None:
                scorer = self._new_scorer()
                if scorer is None:
                    self._stopping.wait(5.0)
                    continue
            submission_id = self.store.claim_next()
            if submission_id is None:
                self._wake.wait(1.0)
                self._wake.clear()
                continue
            started = time.monotonic()
            try:
                scorer.ask(submission_id)
                answer = scorer.answer(self.settings.time_limit_s)
            except TimeoutError:
                self._drop(scorer)
                scorer = None
                self.store.record_failure(
                    submission_id, f"scoring took longer than the limit of {self.settings.time_limit_s:g} s"
                )
                log.warning("submission %d: time limit, scorer killed", submission_id)
                continue
            except (ScorerFailed, OSError) as exc:
                self._drop(scorer)
                scorer = None
                if self._stopping.is_set():
                    self.store.release(submission_id)
                else:
                    log.warning("submission %d: %s", submission_id, exc)
                    self.store.record_failure(
                        submission_id,
                        f"the scorer stopped while scoring this submission (memory limit {self.settings.memory_mb} MB)",
                    )
                continue
            if answer.get("ok"):
                self.store.record_score(submission_id, answer["sha256"], answer["scores"])
                log.info("submission %d scored in %.1f s", submission_id, time.monotonic() - started)
            else:
                self.store.record_failure(submission_id, answer["error"])
                log.info("submission %d failed: %s", submission_id, answer["error"])
        if scorer is not None:
            self._drop(scorer)
