"""The ``--out`` directory of ``zendar-bench``: whose it is, and which of its steps are already done.

A run directory carries ``zendar-bench.json`` (what made it). ``zendar-bench`` writes only into an
empty or missing directory or one of its own; a directory holding anything else is refused before a
byte is written. Each step records ``<step>/step.json`` with a SHA-256 of its inputs (configuration,
dataset fingerprint, code version, upstream steps' keys); a step whose record matches is reused, so
an interrupted bench resumes where it stopped and an edited source file recomputes what it touches.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from zendar_dataset.errors import ZendarError
from zendar_dataset.output_location import other_entries
from zendar_dataset.atomic_files import prepare_out_dir, write_json_atomic

from zendar_baselines.fingerprints import canonical_json_sha256

RUN_MARKER = "zendar-bench.json"
RUN_FORMAT = "zendar-bench-run"
STEP_RECORD = "step.json"


def read_json(path: Path) -> Any:
    """JSON of a file the bench wrote; ZendarError naming the file when it cannot be read as such."""
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ZendarError(f"{path}: cannot be read as the JSON zendar-bench wrote ({exc})") from None


class RunDirectory:
    """An output directory owned by ``zendar-bench``.

    Parameters
    ----------
    path
        The ``--out`` directory.
    identity
        What the run is (configuration name, dataset); recorded in :data:`RUN_MARKER`.

    Raises
    ------
    ZendarError
        When ``path`` holds files but no marker of ours (nothing is touched), or the marker says
        another configuration made it.
    """

    def __init__(self, path: str | os.PathLike, identity: dict[str, Any]) -> None:
        self.path = Path(path)
        if self.check_owner(self.path, identity) is None:
            prepare_out_dir(self.path)
            write_json_atomic(self.path / RUN_MARKER, {"format": RUN_FORMAT, "format_version": 1, "identity": identity})
        self.identity = identity

    @classmethod
    def check_owner(cls, path: Path, identity: dict[str, Any]) -> dict[str, Any] | None:
        """:meth:`owner_record`, refusing a run whose identity differs from ``identity`` in any key it gives.

        Called with part of the identity (the configuration) before any work starts, and with all
        of it once the dataset is known.
        """
        recorded = cls.owner_record(path)
        if recorded is not None:
            theirs = recorded.get("identity")
            if not isinstance(theirs, dict) or any(theirs.get(key) != value for key, value in identity.items()):
                raise ZendarError(
                    f"--out {path} holds a zendar-bench run of {theirs}, not of {identity}; "
                    "choose another --out (nothing was changed)"
                )
        return recorded

    @staticmethod
    def owner_record(path: Path) -> dict[str, Any] | None:
        """The run record of ``path``, or None for a missing or empty directory.

        Raises
        ------
        ZendarError
            When ``path`` is a file, or holds files but no record of ours (checked before any work
            starts, so that nothing is simulated or trained for an output that will be refused).
        """
        marker = path / RUN_MARKER
        if path.exists() and not path.is_dir():
            raise ZendarError(f"--out {path}: exists and is not a directory")
        if marker.is_file():
            recorded = read_json(marker)
            if not isinstance(recorded, dict) or recorded.get("format") != RUN_FORMAT:
                raise ZendarError(f"{marker}: not a zendar-bench run record; choose another --out")
            return recorded
        found = other_entries(path) if path.is_dir() else None
        if found:
            raise ZendarError(
                f"--out {path} holds files that zendar-bench did not write ({found}); "
                "choose an empty or new directory (nothing was changed)"
            )
        return None

    def is_done(self, name: str, inputs: dict[str, Any]) -> bool:
        """Whether step ``name`` finished with these ``inputs`` (its record holds their key)."""
        record = self.path / name / STEP_RECORD
        try:
            done = json.loads(record.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError):
            return False
        return isinstance(done, dict) and done.get("key") == canonical_json_sha256(inputs)

    def step(self, name: str, inputs: dict[str, Any], compute: Callable[[Path], Any]) -> tuple[Path, str, bool]:
        """Run ``compute(step_dir)`` unless the step is done with the same inputs.

        Returns
        -------
        step_dir, key, reused
            The step's directory, the key of its inputs (for downstream steps' inputs), and
            whether a finished result was reused.
        """
        key = canonical_json_sha256(inputs)
        step_dir = self.path / name
        if self.is_done(name, inputs):
            print(f"[{name}] reused: done before with the same inputs", file=sys.stderr, flush=True)
            return step_dir, key, True
        record = step_dir / STEP_RECORD
        if record.is_file():
            # Our own step made with other inputs: its files are stale, start it over. (An interrupted
            # step has no record: its files stay, and training resumes from its checkpoints.)
            shutil.rmtree(step_dir)
        prepare_out_dir(step_dir)
        started = time.monotonic()
        compute(step_dir)
        elapsed_s = round(time.monotonic() - started, 1)
        write_json_atomic(record, {"key": key, "inputs": inputs, "elapsed_s": elapsed_s})
        print(f"[{name}] done in {elapsed_s:.1f} s", file=sys.stderr, flush=True)
        return step_dir, key, False
