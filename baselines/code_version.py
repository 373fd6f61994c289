"""The version of the code that made a cached result: package version plus a hash of the sources.

Cached steps of ``zendar-bench`` (automatic labels, checkpoints, predictions) record it and are
reused only when it matches, so an edited source file never silently reuses an old result.
"""

from __future__ import annotations

import hashlib
from functools import lru_cache
from pathlib import Path

import zendar_dataset

import zendar_baselines


@lru_cache(maxsize=1)
def code_version() -> str:
    """``"<package version>+<first 12 hex of SHA-256 over every .py file of both packages>"``."""
    digest = hashlib.sha256()
    for package in (zendar_dataset, zendar_baselines):
        root = Path(package.__file__).resolve().parent
        for path in sorted(root.rglob("*.py")):
            if "__pycache__" in path.parts:
                continue
            digest.update(path.relative_to(root).as_posix().encode())
            digest.update(b"\0")
            digest.update(path.read_bytes())
    return f"{zendar_dataset.__version__}+{digest.hexdigest()[:12]}"
