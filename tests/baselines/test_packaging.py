"""The baselines install as ``zendar_baselines`` (never a bare ``baselines``) with the ``zendar-bench`` script."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_every_baselines_folder_is_listed_in_pyproject():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    setuptools = config["tool"]["setuptools"]
    assert setuptools["package-dir"]["zendar_baselines"] == "baselines"
    found = {
        ".".join(("zendar_baselines", *init.parent.relative_to(ROOT / "baselines").parts))
        for init in (ROOT / "baselines").rglob("__init__.py") if "__pycache__" not in init.parts
    }
    assert found - set(setuptools["packages"]) == set(), "add these packages to pyproject.toml"
    assert "baselines" not in setuptools["packages"]
    assert config["project"]["scripts"]["zendar-bench"] == "zendar_baselines.entry:zendar_bench"


def test_the_import_name_is_zendar_baselines_only(tmp_path):
    code = "import zendar_baselines.entry, importlib.util; print(importlib.util.find_spec('baselines'))"
    completed = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert completed.returncode == 0, completed.stderr
    assert completed.stdout.strip() == "None"
