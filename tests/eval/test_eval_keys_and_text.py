"""Keys given twice, text that is not Unicode, unwritable meta values and over-long integers: each named."""

import json
import warnings

import pytest

from zendar_dataset.cli.eval import main
from zendar_dataset.errors import PredictionsError
from zendar_dataset.eval import evaluate
from zendar_dataset.eval import validation
from zendar_dataset.eval.validation import duplicate_key_problems, load_document

GT = {"frames": {f"s/{k}": [{"x": 20.0 + k, "y": 0.0}] for k in range(4)}}


def _detection(k, score=0.9):
    return f'{{"x": {20.0 + k}, "y": 0.0, "score": {score}}}'


def _predictions_text(frames: list[str], meta: str = '{"method": "m"}') -> str:
    """Predictions written by hand, so that a key can be given twice."""
    return f'{{"meta": {meta}, "results": {{{", ".join(frames)}}}}}'


def _frame(k, detections=None):
    return f'"s/{k}": [{_detection(k) if detections is None else detections}]'


def _run(tmp_path, capsys, text, *extra):
    (tmp_path / "p.json").write_text(text, encoding="utf-8")
    (tmp_path / "g.json").write_text(json.dumps(GT))
    status = main([str(tmp_path / "p.json"), "--gt", str(tmp_path / "g.json"), *extra])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def test_every_repeated_frame_id_is_named_with_the_other_problems(tmp_path, capsys):
    # s/1 twice (the last copy, a miss, would lower the score), s/2 three times, and a NaN elsewhere.
    frames = [_frame(0), _frame(1), _frame(1, ""), _frame(2), _frame(2), _frame(2), _frame(3, '{"x": NaN, "y": 0, "score": 1}')]
    status, out, err = _run(tmp_path, capsys, _predictions_text(frames))
    assert status == 2 and out == "" and "Traceback" not in err and "a bug" not in err
    assert "predictions: frame 's/1' is given 2 times in 'results'" in err
    assert "predictions: frame 's/2' is given 3 times in 'results'" in err
    assert "predictions frame 's/3' detection 0: 'x' is not finite (nan)" in err


def test_repeated_keys_of_meta_detections_and_ground_truth_are_named():
    text = _predictions_text(
        [_frame(0, '{"x": 20, "y": 0, "score": 0.5, "score": 0.9}')], meta='{"method": "a", "method": "b"}'
    )
    assert duplicate_key_problems(text.encode(), json.loads(text), what="predictions") == [
        "predictions: key 'method' is given 2 times in 'meta'",
        "predictions frame 's/0' detection 0: 'score' is given 2 times",
    ]
    gt_text = '{"split": "test", "frames": {"s/0": [], "s/0": []}, "split": "val"}'
    assert duplicate_key_problems(gt_text.encode(), json.loads(gt_text), what="ground truth") == [
        "ground truth: key 'split' is given 2 times at the top level",
        "ground truth: frame 's/0' is given 2 times in 'frames' (a JSON reader keeps only the last)",
    ]


def test_ground_truth_file_with_a_repeated_frame_is_refused(tmp_path):
    (tmp_path / "g.json").write_text('{"frames": {"s/0": [{"x": 20, "y": 0}], "s/0": []}}')
    with pytest.raises(PredictionsError, match="ground truth: frame 's/0' is given 2 times in 'frames'"):
        evaluate({"results": {"s/0": []}}, str(tmp_path / "g.json"))


@pytest.mark.parametrize(
    "text",
    [
        # Colons inside strings (keys and values), some written as the escape \u003a, and keys
        # spaced from their colon: none of them may hide the repeat from the fast count.
        _predictions_text([_frame(0), _frame(1), _frame(0)], meta='{"method": "a:b", "url": "http\\u003a//x"}'),
        _predictions_text([_frame(0), _frame(0)], meta='{"method" : "a\\u003ab\\u003ac", "tags": ["x:y", {"k:": 1}]}'),
        _predictions_text(['"s/0" :\n[' + _detection(0) + "]", '"s/0":[]']),
    ],
)
def test_a_repeat_is_found_whatever_the_strings_and_spacing(tmp_path, text):
    path = tmp_path / "p.json"
    path.write_text(text)
    _, problems = load_document(path, what="predictions")
    assert any("frame 's/0' is given" in problem for problem in problems), problems


@pytest.mark.parametrize(
    "text",
    [
        _predictions_text([_frame(k) for k in range(4)], meta='{"method": "a:b", "url": "http://x:80/"}'),
        _predictions_text([_frame(k) for k in range(4)], meta='{"method": "a\\u003ab", "note": "\\"q\\": 1"}'),
        json.dumps({"meta": {"method": "m"}, "results": {f"s/{k}": [{"x": 20.0 + k, "y": 0.0, "score": 0.5}] for k in range(4)}}, indent=2),
    ],
)
def test_a_file_without_repeats_takes_the_fast_path(tmp_path, monkeypatch, text):
    def exact_pass(*args):
        raise AssertionError("the slow exact pass ran on a file without repeated keys")

    monkeypatch.setattr(validation, "_repeated_key_problems", exact_pass)
    path = tmp_path / "p.json"
    path.write_text(text)
    document, problems = load_document(path, what="predictions")
    assert problems == [] and evaluate(document, GT)["ap"]["all"] == 1.0


def test_a_lone_surrogate_in_meta_is_named_and_valid_text_is_printed_and_written(tmp_path, capsys):
    status, out, err = _run(tmp_path, capsys, _predictions_text([_frame(k) for k in range(4)], '{"method": "\\ud800"}'))
    assert status == 2 and out == "" and "a bug" not in err
    assert "predictions: 'meta.method' is not valid Unicode text: it holds a lone surrogate ('\\ud800') at character 1" in err
    nested = '{"method": "m", "team": {"names": ["ok", "x\\udfffy"], "\\udc80": 1}}'
    status, out, err = _run(tmp_path, capsys, _predictions_text([_frame(k) for k in range(4)], nested))
    assert status == 2
    assert "'meta.team.names[1]' is not valid Unicode text: it holds a lone surrogate ('\\udfff') at character 2" in err
    assert "a key of 'meta.team' ('\\udc80') is not valid Unicode text" in err
    # A real pair, escaped or not, is text: printed, and kept in metrics.json.
    meta = '{"method": "caf\\u00e9 \\ud83d\\ude00 ✓", "team": "Zürich"}'
    status, out, err = _run(tmp_path, capsys, _predictions_text([_frame(k) for k in range(4)], meta), "--out", str(tmp_path / "o"))
    assert status == 0 and "method: café 😀 ✓" in out
    written = json.loads((tmp_path / "o" / "metrics.json").read_text(encoding="utf-8"))
    assert written["meta"] == {"method": "café 😀 ✓", "team": "Zürich"}


def test_meta_values_metrics_json_cannot_hold_are_refused(tmp_path, capsys):
    meta = '{"method": "m", "a": NaN, "b": [1, -Infinity], "c": 1' + "0" * 5000 + "}"
    status, out, err = _run(tmp_path, capsys, _predictions_text([_frame(k) for k in range(4)], meta), "--out", str(tmp_path / "o"))
    assert status == 2 and "a bug" not in err
    assert "'meta.a' is not finite (nan)" in err and "'meta.b[1]' is not finite (-inf)" in err
    assert "'meta.c' is an integer of 5,001 digits, too long to read" in err
    assert not (tmp_path / "o" / "metrics.json").exists()
    with pytest.raises(PredictionsError, match=r"'meta.when' is not a JSON value \(got set\)"):
        evaluate({"meta": {"when": {1}}, "results": {f"s/{k}": [] for k in range(4)}}, GT)


def test_a_lone_surrogate_in_the_ground_truth_split_is_named(tmp_path):
    (tmp_path / "g.json").write_text('{"split": "te\\udc00st", "frames": {"s/0": []}}')
    with pytest.raises(PredictionsError, match=r"ground truth: 'split' is not valid Unicode text"):
        evaluate({"results": {"s/0": []}}, str(tmp_path / "g.json"))


def test_an_over_long_integer_is_named_where_it_is(tmp_path, capsys):
    huge = "1" * 4301
    frames = [_frame(0, f'{{"x": {huge}, "y": 0, "score": 0.5}}'), _frame(1), _frame(2, f'{{"x": 1, "y": -{huge}, "score": 0.5}}'), _frame(3)]
    status, out, err = _run(tmp_path, capsys, _predictions_text(frames))
    assert status == 2 and "Exceeds the limit" not in err
    assert "predictions frame 's/0' detection 0: 'x' holds a number that cannot be read (an integer of 4,301 digits; the limit is 4300)" in err
    assert "predictions frame 's/2' detection 0: 'y' holds a number that cannot be read (an integer of 4,301 digits; the limit is 4300)" in err


def test_no_warning_on_valid_files(tmp_path, capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        status, out, _ = _run(tmp_path, capsys, _predictions_text([_frame(k) for k in range(4)]))
    assert status == 0 and "method: m" in out


def test_a_repeat_nested_deeper_than_pythons_parser_reads_is_a_problem_not_a_crash(tmp_path, capsys):
    depth = 1000  # orjson reads it; Python's json, which names repeats, runs out of recursion
    text = _predictions_text([_frame(k) for k in range(4)])[:-1] + ', "x": ' + "[" * depth + "]" * depth + ', "x": 1}'
    status, _, err = _run(tmp_path, capsys, text)
    assert status == 2 and "Traceback" not in err and "a bug" not in err
    assert "given more than once" in err


def test_meta_from_python_may_hold_tuples_and_number_keys_as_json_writes_them():
    predictions = {"meta": {"method": "m", "tags": ("a", "b"), "by_epoch": {1: 0.5}},
                   "results": {f"s/{k}": [{"x": 20.0 + k, "y": 0.0, "score": 0.9}] for k in range(4)}}
    metrics = evaluate(predictions, GT)
    assert metrics["ap"]["all"] == pytest.approx(1.0) and list(metrics["meta"]["tags"]) == ["a", "b"]
