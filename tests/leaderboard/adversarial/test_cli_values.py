"""Values a command line cannot mean are refused by argument parsing (exit 2, one line naming the
option), before a database is opened or anything is sent to a server."""

from __future__ import annotations

import pytest

from zendar_leaderboard import client
from zendar_leaderboard.cli import build_parser, main
from zendar_leaderboard.store import Store

TOO_LARGE_ID = "99999999999999999999999"  # above SQLite's 64-bit INTEGER


def refused(capsys, *args) -> str:
    """stderr of ``main(args)``, which must exit 2 from argument parsing without a bug's message."""
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_status:
        main([str(a) for a in args])
    err = capsys.readouterr().err
    assert exit_status.value.code == 2, err
    assert "unexpected" not in err and "Traceback" not in err
    return err


def refused_by_parsing(capsys, *args) -> str:
    """stderr of parsing ``args`` alone, which must exit 2: a value let through fails the test instead of
    starting a server that runs until stopped."""
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_status:
        build_parser().parse_args([str(a) for a in args])
    err = capsys.readouterr().err
    assert exit_status.value.code == 2, err
    return err


@pytest.fixture
def nothing_sent(monkeypatch):
    """Fail the test at the first request ``submit`` would send."""

    def request(url, *args, **kwargs):
        raise AssertionError(f"a request was sent to {url}")

    monkeypatch.setattr(client, "_request", request)


@pytest.mark.parametrize("command", ["delete", "hide", "unhide"])
@pytest.mark.parametrize("submission_id", [TOO_LARGE_ID, "0", "-1"])
def test_a_submission_id_out_of_range_is_refused_and_the_database_left_alone(tmp_path, capsys, command, submission_id):
    store = Store(tmp_path / "board.db")
    store.add_team("t")
    generation = store.generation()
    err = refused(capsys, command, "--db", store.path, "--", submission_id)
    assert f"ID must be between 1 and 9,223,372,036,854,775,807, got {int(submission_id)}" in err
    assert store.generation() == generation


@pytest.mark.parametrize("port, says", [
    ("70000", "--port must be between 0 and 65,535, got 70000"),
    ("65536", "--port must be between 0 and 65,535, got 65536"),
    ("-1", "--port must be between 0 and 65,535, got -1"),
    ("http", "invalid int value: 'http'"),
])
def test_a_port_out_of_range_is_refused_by_argument_parsing(capsys, port, says):
    assert says in refused_by_parsing(capsys, "serve", "--gt", "gt.json", "--db", "board.db", f"--port={port}")


@pytest.mark.parametrize("value", ["nan", "inf", "0", "-5"])
def test_a_scoring_time_limit_that_is_not_a_positive_finite_number_is_refused(capsys, value):
    err = refused_by_parsing(capsys, "serve", "--gt", "gt.json", "--db", "board.db", f"--time-limit-s={value}")
    assert "--time-limit-s must be" in err


@pytest.mark.parametrize("option, value, says", [
    ("--time-limit-s", "1e308", "--time-limit-s must be at most 604,800, got 1e308"),
    ("--upload-deadline-s", "1e12", "--upload-deadline-s must be at most 604,800, got 1e12"),
    ("--memory-mb", str(2**60), f"--memory-mb must be between 1 and 8,388,608, got {2**60}"),
])
def test_a_serve_limit_beyond_what_the_os_can_honour_is_refused(capsys, option, value, says):
    # 1e308 s overflows the scheduler's queue timeout and the socket timeout; 2**60 MB the address-space limit.
    assert says in refused_by_parsing(capsys, "serve", "--gt", "gt.json", "--db", "board.db", f"{option}={value}")


@pytest.mark.parametrize("value", ["-1", "0", "nan", "inf", "1e308"])
def test_a_submit_timeout_that_is_not_a_positive_finite_number_is_refused_before_the_upload(
    tmp_path, gt_file, capsys, nothing_sent, value
):
    gt_path, _ = gt_file
    err = refused(capsys, "submit", gt_path, "--server", "http://127.0.0.1:8000", "--token", "t",
                  f"--timeout-s={value}")
    assert "--timeout-s must be" in err


@pytest.mark.parametrize("url, reason", [
    ("notaurl", "expected http://HOST[:PORT]"),
    ("ftp://example.org", "expected http://HOST[:PORT]"),
    ("http:///api", "expected http://HOST[:PORT]"),
    ("http://127.0.0.1:99999/", "the port must be a number from 1 to 65535"),
    ("http://127.0.0.1:0", "the port must be a number from 1 to 65535"),
    ("http://127.0.0.1:port", "the port must be a number from 1 to 65535"),
    ("http://[::1", "Invalid IPv6 URL"),
    ("http://board example.org", "it holds a space or a control character"),
    ("http://127.0.0.1:8000/?round=2", "a query, fragment or user name cannot be part of it"),
    ("http://user:secret@127.0.0.1:8000", "a query, fragment or user name cannot be part of it"),
])
def test_a_server_url_that_cannot_name_a_server_is_refused_before_anything_is_sent(
    tmp_path, gt_file, capsys, nothing_sent, url, reason
):
    gt_path, _ = gt_file
    err = refused(capsys, "submit", gt_path, "--server", url, "--token", "t")
    assert f"invalid --server URL {url!r}: {reason}" in err


@pytest.mark.parametrize("url", ["http://127.0.0.1:8000", "https://board.example.org/round-2/", "http://[::1]:80"])
def test_a_server_url_with_a_host_port_and_path_is_taken(url):
    assert client.check_server_url(url) == url
