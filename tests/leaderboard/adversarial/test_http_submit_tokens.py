"""``submit`` takes the token from a file or the environment, so that ``ps`` does not show it;
``--token`` still works, with a warning."""

from __future__ import annotations

import json

import pytest

from tests.leaderboard.conftest import ground_truth, submission
from zendar_leaderboard.cli import TOKEN_VARIABLE, main


@pytest.fixture
def submission_file(tmp_path):
    path = tmp_path / "submission.json"
    path.write_text(json.dumps(submission(ground_truth())))
    return path


def _submit(board, submission_file, *extra: str) -> int:
    return main(["submit", str(submission_file), "--server", board.url, "--no-wait", *extra])


def test_the_token_comes_from_a_file(board, submission_file, tmp_path, capsys, monkeypatch):
    monkeypatch.delenv(TOKEN_VARIABLE, raising=False)
    token_file = tmp_path / "token"
    token_file.write_text(board.store.add_team("token-file") + "\n")
    assert _submit(board, submission_file, "--token-file", str(token_file)) == 0
    captured = capsys.readouterr()
    assert "queued" in captured.out and "warning" not in captured.err


def test_the_token_comes_from_the_environment(board, submission_file, capsys, monkeypatch):
    monkeypatch.setenv(TOKEN_VARIABLE, board.store.add_team("token-env"))
    assert _submit(board, submission_file) == 0
    assert "queued" in capsys.readouterr().out


def test_a_token_on_the_command_line_works_with_a_warning(board, submission_file, capsys, monkeypatch):
    monkeypatch.delenv(TOKEN_VARIABLE, raising=False)
    assert _submit(board, submission_file, "--token", board.store.add_team("token-argument")) == 0
    captured = capsys.readouterr()
    assert "queued" in captured.out
    assert "--token is visible to every user of this machine" in captured.err


@pytest.mark.parametrize(
    ("arguments", "message"),
    [((), "no token: give --token-file PATH"), (("--token-file", "/nonexistent/token"), "cannot read the token file")],
    ids=["none", "missing-file"],
)
def test_no_token_is_a_user_error(board, submission_file, capsys, monkeypatch, arguments, message):
    monkeypatch.delenv(TOKEN_VARIABLE, raising=False)
    assert _submit(board, submission_file, *arguments) == 2
    assert message in capsys.readouterr().err


def test_no_token_reads_as_an_option_on_a_command_line(tmp_path):
    # A URL-safe token starting with "-" made `submit --token -x…` an unknown-option error.
    from zendar_leaderboard.store import Store

    store = Store(tmp_path / "board.db")
    tokens = [store.add_team(f"team {k}") for k in range(300)]
    assert not [token for token in tokens if token.startswith("-")]
    assert all(len(token) == 64 and int(token, 16) >= 0 for token in tokens)
