"""The shared checks of command-line values: a bad value stops parsing with one error line and exit 2."""

from __future__ import annotations

import argparse

import pytest

from zendar_dataset.cli.arguments import number_between, positive_number, seed_count, split_ratios, whole_number
from zendar_leaderboard.cli import main as zendar_leaderboard


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="tool")
    parser.add_argument("--seed", type=whole_number("--seed", 0), default=0)
    parser.add_argument("--bootstrap", type=whole_number("--bootstrap", 0, 100_000), default=0)
    parser.add_argument("--time-limit-s", type=positive_number("--time-limit-s"), default=1.0)
    parser.add_argument("--seeds", type=seed_count(100), default=None)
    parser.add_argument("--split-ratios", type=split_ratios, default=(0.6, 0.2, 0.2))
    parser.add_argument("--tolerance-ms", type=number_between("--tolerance-ms", 0, 1_000), default=None)
    return parser


def _error_lines(capsys, args: list[str]) -> list[str]:
    with pytest.raises(SystemExit) as exited:
        _parser().parse_args(args)
    assert exited.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return [line for line in err.splitlines() if "error:" in line]


def test_good_values_are_converted():
    args = _parser().parse_args(
        ["--seed", "0", "--bootstrap", "100000", "--time-limit-s", "0.5", "--seeds", "3", "--split-ratios", "1,0,0",
         "--tolerance-ms", "1000"]
    )
    assert (args.seed, args.bootstrap, args.time_limit_s, args.seeds, args.split_ratios, args.tolerance_ms) == (
        0, 100_000, 0.5, 3, (1.0, 0.0, 0.0), 1000.0
    )


@pytest.mark.parametrize(
    ("args", "line"),
    [
        (["--seed", "-1"], "tool: error: --seed must be 0 or more, got -1"),
        (["--bootstrap", "100001"], "tool: error: --bootstrap must be between 0 and 100,000, got 100001"),
        (["--bootstrap", "-3"], "tool: error: --bootstrap must be between 0 and 100,000, got -3"),
        (["--time-limit-s", "0"], "tool: error: --time-limit-s must be positive, got 0.0"),
        (["--seed", "x"], "tool: error: argument --seed: invalid int value: 'x'"),
        (["--time-limit-s", "soon"], "tool: error: argument --time-limit-s: invalid float value: 'soon'"),
        (["--seeds", "0"], "tool: error: argument --seeds: expected 1 to 100 seeds, got 0"),
        (["--seeds", "three"], "tool: error: argument --seeds: expected a whole number of seeds, got 'three'"),
        (["--split-ratios", "1,2"], "tool: error: argument --split-ratios: expected three numbers (train,val,test), got '1,2'"),
        (["--time-limit-s", "nan"], "tool: error: --time-limit-s must be a finite number, got nan"),
        (["--time-limit-s", "inf"], "tool: error: --time-limit-s must be a finite number, got inf"),
        (["--tolerance-ms=-0.5"], "tool: error: --tolerance-ms must be between 0 and 1,000, got -0.5"),
        (["--tolerance-ms", "1e308"], "tool: error: --tolerance-ms must be between 0 and 1,000, got 1e308"),
        (["--tolerance-ms", "NaN"], "tool: error: --tolerance-ms must be a finite number, got NaN"),
        (["--tolerance-ms", "soon"], "tool: error: argument --tolerance-ms: invalid float value: 'soon'"),
        (["--split-ratios", "nan,0,1"], "tool: error: argument --split-ratios: expected finite shares of 0 or more "
         "(train,val,test) with a positive, finite sum, got 'nan,0,1'"),
        (["--split-ratios", "1e308,1e308,1e308"], "tool: error: argument --split-ratios: expected finite shares of 0 "
         "or more (train,val,test) with a positive, finite sum, got '1e308,1e308,1e308'"),
        (["--split-ratios", "0,0,0"], "tool: error: argument --split-ratios: expected finite shares of 0 or more "
         "(train,val,test) with a positive, finite sum, got '0,0,0'"),
        (["--split-ratios=-1,1,1"], "tool: error: argument --split-ratios: expected finite shares of 0 or more "
         "(train,val,test) with a positive, finite sum, got '-1,1,1'"),
    ],
)
def test_a_bad_value_exits_2_with_one_error_line(capsys, args, line):
    assert _error_lines(capsys, args) == [line]


def test_a_tool_refuses_a_bad_value_before_any_work(capsys, tmp_path):
    with pytest.raises(SystemExit) as exited:
        zendar_leaderboard(["serve", "--gt", str(tmp_path / "gt.json"), "--db", str(tmp_path / "b.db"), "--workers", "0"])
    assert exited.value.code == 2
    err = capsys.readouterr().err
    assert [line for line in err.splitlines() if "error:" in line] == [
        "zendar-leaderboard serve: error: --workers must be 1 or more, got 0"
    ]
    assert not (tmp_path / "b.db").exists()
