"""Bad arguments and odd values for the evaluator: a message and exit status 2, never a traceback;
numpy scalars from an API caller are numbers; a flood of problems is summarised."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.reliability.outputs_helpers import assert_one_line_failure, run_in_process, run_tool
from zendar_dataset.errors import ZendarError
from zendar_dataset.eval import evaluate
from zendar_dataset.eval.protocol import MAX_BOOTSTRAP_RESAMPLES

GROUND_TRUTH = {"frames": {"s/1": [{"x": 10.0, "y": 0.0}, {"x": 40.0, "y": 3.0}], "s/2": [{"x": 20.0, "y": -5.0}]}}
PREDICTIONS = {
    "meta": {"method": "m"},
    "results": {
        "s/1": [{"x": 10.5, "y": 0.0, "score": 0.9}, {"x": 25.0, "y": 25.0, "score": 0.8}],
        "s/2": [{"x": 20.0, "y": -4.0, "score": 0.7}],
    },
}


@pytest.fixture
def files(tmp_path):
    gt, pred = tmp_path / "gt.json", tmp_path / "pred.json"
    gt.write_text(json.dumps(GROUND_TRUTH))
    pred.write_text(json.dumps(PREDICTIONS))
    return gt, pred


ARGUMENT_CASES = {
    "seed-negative": (["--bootstrap", "10", "--seed", "-1"], "--seed must be 0 or more"),
    "bootstrap-huge": (["--bootstrap", "100000000000"], f"between 0 and {MAX_BOOTSTRAP_RESAMPLES:,}"),
    "bootstrap-negative": (["--bootstrap", "-3"], "--bootstrap must be between 0 and"),
}


@pytest.mark.parametrize("case", sorted(ARGUMENT_CASES))
def test_bad_arguments_exit_2_with_a_message(files, case):
    gt, pred = files
    args, fragment = ARGUMENT_CASES[case]
    result = run_in_process("zendar-eval", pred, "--gt", gt, *args)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert fragment in result.stderr


@pytest.mark.parametrize("where", ["predictions", "ground truth"])
def test_an_integer_literal_over_4300_digits_is_a_problem_not_a_crash(tmp_path, files, where):
    gt, pred = files
    huge = "7" * 4400
    if where == "predictions":
        pred.write_text('{"results": {"s/1": [{"x": ' + huge + ', "y": 0, "score": 0.5}], "s/2": []}}')
    else:
        gt.write_text('{"frames": {"s/1": [{"x": ' + huge + ', "y": 0}], "s/2": []}}')
    result = run_in_process("zendar-eval", pred, "--gt", gt)
    line = assert_one_line_failure(result, 2, "cannot be read", where)
    assert "4300" in line


API_CASES = {
    "max_bytes-text": ({"max_bytes": "x"}, "max_bytes must be an integer"),
    "max_bytes-zero": ({"max_bytes": 0}, "max_bytes must be 1 or more"),
    "seed-negative": ({"seed": -1, "bootstrap": 5}, "seed must be 0 or more"),
    "seed-float": ({"seed": 1.5}, "seed must be an integer"),
    "bootstrap-huge": ({"bootstrap": 100_000_000_000}, "bootstrap must be between 0 and 100,000"),
    "bootstrap-bool": ({"bootstrap": True}, "bootstrap must be an integer"),
}


@pytest.mark.parametrize("case", sorted(API_CASES))
def test_api_arguments_are_checked_before_any_work(case):
    kwargs, message = API_CASES[case]
    with pytest.raises(ZendarError, match=message):
        evaluate(PREDICTIONS, GROUND_TRUTH, **kwargs)


@pytest.mark.parametrize("kind", [np.float64, np.float32, np.int64, np.int32])
def test_numpy_scalars_from_an_api_caller_are_numbers(kind):
    def document(key, source, number):
        return {
            key: {
                frame: [
                    {name: (np.float64(v) if name == "score" else number(kind(v))) for name, v in car.items()}
                    for car in cars
                ]
                for frame, cars in source[key].items()
            }
        }

    with_numpy = evaluate(document("results", PREDICTIONS, lambda v: v), document("frames", GROUND_TRUTH, lambda v: v))
    plain = evaluate(document("results", PREDICTIONS, float), document("frames", GROUND_TRUTH, float))
    assert with_numpy["ap"] == plain["ap"] and with_numpy["counts"] == plain["counts"]
    # By hand: (10.5, 0) matches (10, 0) and (20, -4) matches (20, -5); (25, 25) and (40, 3) stay alone.
    assert plain["counts"]["all"] == {"gt": 3, "tp": 2, "fp": 1}
    # numpy's bool is no number, as Python's is not.
    flagged = {"results": {"s/1": [{"x": np.bool_(True), "y": kind(0), "score": 0.5}], "s/2": []}}
    with pytest.raises(ZendarError, match="'x' must be a number, got bool"):
        evaluate(flagged, GROUND_TRUTH)


@pytest.fixture
def twelve_thousand_problems(tmp_path):
    frames = {f"s/{k}": [] for k in range(4000)}
    results = {frame: [{"x": "a", "y": None, "score": "b"}] for frame in frames}  # 3 problems per frame
    gt, pred = tmp_path / "gt.json", tmp_path / "pred.json"
    gt.write_text(json.dumps({"frames": frames}))
    pred.write_text(json.dumps({"results": results}))
    return gt, pred


def test_a_flood_of_problems_prints_the_first_50_and_the_count(twelve_thousand_problems):
    gt, pred = twelve_thousand_problems
    result = run_in_process("zendar-eval", pred, "--gt", gt)
    lines = result.stderr.splitlines()
    assert result.returncode == 2
    assert lines[0] == "error: 12000 problems found:"
    assert len(lines) == 52 and lines[-1] == "  ... and 11950 more, 12000 problems in all"


def test_with_out_the_full_list_goes_to_a_file_and_the_message_says_where(tmp_path, twelve_thousand_problems):
    gt, pred = twelve_thousand_problems
    out = tmp_path / "out"
    result = run_tool("zendar-eval", pred, "--gt", gt, "--out", out)
    listed = (out / "problems.txt").read_text().splitlines()
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert len(listed) == 12000 and listed[0].startswith("predictions frame 's/0' detection 0: 'x'")
    assert f"all of them are in {out / 'problems.txt'}" in result.stderr.splitlines()[0]
    assert len(result.stderr.splitlines()) == 52
    assert not (out / "metrics.json").exists()
