"""HTTP helpers of the leaderboard tests (standard library only)."""

from __future__ import annotations

import json
import time
import urllib.error
import urllib.request


def request(url: str, *, token: str | None = None, body: bytes | None = None, method: str | None = None):
    """(status, parsed JSON or text) of one request."""
    req = urllib.request.Request(url, data=body, method=method or ("POST" if body is not None else "GET"))
    if token is not None:
        req.add_header("Authorization", f"Bearer {token}")
    try:
        with urllib.request.urlopen(req, timeout=60) as response:
            status, raw, kind = response.status, response.read(), response.headers.get("Content-Type", "")
    except urllib.error.HTTPError as exc:
        status, raw, kind = exc.code, exc.read(), exc.headers.get("Content-Type", "")
    return status, json.loads(raw) if "json" in kind else raw.decode()


def post_submission(url: str, token: str, document) -> tuple[int, dict]:
    body = document if isinstance(document, bytes) else json.dumps(document).encode()
    return request(f"{url}/api/submissions", token=token, body=body)


def wait_done(url: str, token: str, submission_id: int, timeout_s: float = 120.0) -> dict:
    """Poll until the submission is scored or failed."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        status, answer = request(f"{url}/api/submissions/{submission_id}", token=token)
        assert status == 200, answer
        if answer["status"] in ("scored", "failed"):
            return answer
        time.sleep(0.1)
    raise AssertionError(f"submission {submission_id} not done after {timeout_s} s: {answer}")


def expected_ap(gt: dict, document: dict, frame_ids) -> dict:
    """The evaluator's AP on ``frame_ids`` as served: a fraction rounded to 0.001 (computed here, independently
    of the server)."""
    from zendar_dataset.eval import evaluate

    part_gt = {"frames": {f: gt["frames"][f] for f in frame_ids}}
    part_pred = {"meta": {}, "results": {f: document["results"][f] for f in frame_ids}}
    return {band: None if ap is None else round(ap, 3) for band, ap in evaluate(part_pred, part_gt)["ap"].items()}
