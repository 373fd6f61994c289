"""The package installs as ``zendar_leaderboard`` and never as a bare ``leaderboard``."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_every_package_folder_is_listed_in_pyproject():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(config["packages"])
    found = {
        ".".join(init.parent.relative_to(ROOT).parts) for init in (ROOT / "zendar_dataset").rglob("__init__.py")
        if "__pycache__" not in init.parts
    }
    assert found - listed == set(), "add these packages to [tool.setuptools] packages in pyproject.toml"
    assert config["package-dir"]["zendar_leaderboard"] == "leaderboard" and "zendar_leaderboard" in listed
    assert "leaderboard" not in listed


def test_the_import_name_is_zendar_leaderboard_only(tmp_path):
    code = "import zendar_leaderboard.cli, importlib.util; print(importlib.util.find_spec('leaderboard'))"
    completed = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert completed.returncode == 0, completed.stderr
    assert completed.stdout.strip() == "None"
