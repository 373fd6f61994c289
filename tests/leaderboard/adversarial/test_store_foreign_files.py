"""A ``--db`` that is not a leaderboard database is the user's mistake: exit 2 naming the file, and
the file is left byte for byte and mode for mode as it was (no tables, no chmod, no WAL files)."""

from __future__ import annotations

import sqlite3
import stat
from pathlib import Path

import pytest

from zendar_dataset.errors import ZendarError
from zendar_leaderboard.cli import main
from zendar_leaderboard.store import Store

READ_COMMANDS = [["list"], ["render", "site"]]
ADMIN_COMMANDS = [["close-round"], ["hide", "1"], ["unhide", "1"], ["delete", "1"]]


def snapshot(folder: Path) -> dict[str, tuple[bytes, int]]:
    """Every file in ``folder`` with its bytes and mode."""
    return {p.name: (p.read_bytes(), stat.S_IMODE(p.stat().st_mode)) for p in sorted(folder.iterdir())}


def run_main(capsys, *args) -> tuple[int, str]:
    capsys.readouterr()
    code = main([str(a) for a in args])
    return code, capsys.readouterr().err


def not_a_database(folder: Path) -> Path:
    path = folder / "notes.db"
    path.write_text("not a db\n")
    path.chmod(0o644)
    return path


def empty_file(folder: Path) -> Path:
    path = folder / "empty.db"
    path.touch()
    path.chmod(0o644)
    return path


def other_programs_database(folder: Path) -> Path:
    path = folder / "places.sqlite"
    with sqlite3.connect(path) as connection:
        connection.execute("CREATE TABLE places (url TEXT)")
    connection.close()
    path.chmod(0o644)
    return path


@pytest.mark.parametrize("command", [["add-team", "x"], *READ_COMMANDS, *ADMIN_COMMANDS])
@pytest.mark.parametrize("make, says", [
    (not_a_database, "is not an SQLite database, so not a leaderboard database"),
    (other_programs_database, "is an SQLite database of something else (tables places)"),
])
def test_a_file_that_is_not_a_leaderboard_database_is_refused_untouched(
    tmp_path, monkeypatch, capsys, command, make, says
):
    path = make(tmp_path)
    before = snapshot(tmp_path)
    monkeypatch.chdir(tmp_path)  # "render site" would write beside it
    code, err = run_main(capsys, command[0], "--db", path, *command[1:])
    assert code == 2, err
    assert says in err and str(path) in err and "left unchanged" in err
    assert snapshot(tmp_path) == before


def test_serve_refuses_a_file_that_is_not_a_database(tmp_path, gt_file, capsys):
    gt_path, _ = gt_file
    path = not_a_database(tmp_path)
    code, err = run_main(capsys, "serve", "--gt", gt_path, "--db", path, "--port", "0")
    assert code == 2 and "is not an SQLite database" in err and str(path) in err
    assert path.read_text() == "not a db\n" and stat.S_IMODE(path.stat().st_mode) == 0o644


@pytest.mark.parametrize("command", [*READ_COMMANDS, *ADMIN_COMMANDS])
def test_an_empty_file_is_not_made_a_database_by_a_command_that_needs_one(tmp_path, monkeypatch, capsys, command):
    path = empty_file(tmp_path)
    monkeypatch.chdir(tmp_path)
    code, err = run_main(capsys, command[0], "--db", path, *command[1:])
    assert code == 2, err
    assert f"{str(path)!r} is empty, not a leaderboard database" in err
    assert snapshot(tmp_path) == {"empty.db": (b"", 0o644)}


def test_add_team_makes_an_empty_file_the_database(tmp_path, capsys):
    path = empty_file(tmp_path)
    code, err = run_main(capsys, "add-team", "Radar Lab", "--db", path)
    assert code == 0, err
    code, _ = run_main(capsys, "list", "--db", path)
    assert code == 0


def test_a_store_that_must_exist_is_not_created(tmp_path):
    with pytest.raises(ZendarError, match="no leaderboard database at"):
        Store(tmp_path / "board.db", existing=True)
    assert list(tmp_path.iterdir()) == []
