"""``zendar-bench``'s commands: without one it is ``run``; ``fit-chain`` is ``python -m zendar_baselines.classical.chain_fit``."""

from __future__ import annotations

import pytest

from zendar_baselines.bench import cli
from zendar_baselines.classical import chain_fit


def _parsed(*args: str) -> dict:
    parsed = vars(cli.build_parser().parse_args(list(args)))
    parsed.pop("command")
    return parsed


@pytest.mark.parametrize("args", [(), ("--quick",), ("--quick", "--seeds", "2", "--out", "o", "--device", "cpu"),
                                  ("--config", "demo", "--data", "d")])
def test_no_command_is_run(args):
    assert _parsed(*args) == _parsed("run", *args)
    assert _parsed(*args)["func"] is cli._bench
    assert cli.build_parser().parse_args(list(args)).command is None


@pytest.mark.parametrize("main", [lambda: cli.main(["fit-chain", "--help"]), lambda: chain_fit.main(["--help"])],
                         ids=["zendar-bench fit-chain", "python -m zendar_baselines.classical.chain_fit"])
def test_fit_chain_help_exits_0(main, capsys):
    with pytest.raises(SystemExit) as exited:
        main()
    assert exited.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: zendar-bench fit-chain ") and "--sweep" in out and "--split SPLIT" in out


def test_fit_chain_takes_chain_fits_arguments():
    args = cli.build_parser().parse_args(["fit-chain", "root", "--sweep"])
    assert (args.func, args.root, args.split, args.sweep) == (cli._fit_chain, "root", "train", True)


def test_options_before_a_command_are_refused(capsys):
    # Parsed as run's, they would be silently replaced by the command's defaults.
    with pytest.raises(SystemExit) as exited:
        cli.main(["--out", "elsewhere", "verify"])
    assert exited.value.code == 2
    assert "zendar-bench: error: 'verify' must come first" in capsys.readouterr().err
