import argparse

from zendar_dataset.cli import data_info
from zendar_dataset.cli.common import run_cli


def run_info(argv):
    parser = argparse.ArgumentParser()
    data_info.register(parser.add_subparsers())
    args = parser.parse_args(["info", *argv])
    return run_cli(lambda: args.func(args))


def test_info_prints_streams_rates_and_residuals(zarr_root, capsys):
    assert run_info([str(zarr_root)]) == 0
    out = capsys.readouterr().out
    assert "split train: 2 scenes" in out and "split test: 1 scenes" in out
    lines = out.splitlines()
    radar = next(line.split() for line in lines if line.strip().startswith("radar/left") and "20.00" in line)
    assert radar[1:] == ["21", "1.000", "20.00"]
    sync = [line.split() for line in lines if line.strip().startswith("camera/front") and "interp" not in line]
    # camera row of alpha's sync table: tolerance 20 ms, all matched, |dt| median 10 ms, max 17 ms.
    assert ["camera/front", "20.0", "10", "0", "0", "10.000", "17.000"] in sync
    tracklog = [line.split() for line in lines if line.strip().startswith("tracklog") and "interp" in line]
    assert tracklog[0] == ["tracklog", "interp", "9", "1", "0", "0.000", "0.000"]
    # The test scene has no labels: no labels row in its sync table.
    gamma = out[out.index("scene gamma"):]
    assert "\n    labels " not in gamma


def test_info_bad_root_and_split_exit_2(zarr_root, tmp_path, capsys):
    assert run_info([str(tmp_path / "missing")]) == 2
    assert "dataset.json" in capsys.readouterr().err
    assert run_info([str(zarr_root), "--split", "bogus"]) == 2
    assert "unknown split 'bogus'" in capsys.readouterr().err
