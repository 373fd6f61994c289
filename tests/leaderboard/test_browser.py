"""End to end as a person does it: the upload form in a real headless Chromium, then the ranking.

Needs Debian's ``chromium`` and ``chromium-driver`` (installed by .ci/run) and Selenium (the test
extra); skipped with a message where they are absent. Screenshots are saved in the test's tmp dir.
"""

from __future__ import annotations

import json
import subprocess

import pytest

from tests.leaderboard.chromium import chromium
from tests.leaderboard.conftest import ground_truth_file, start_server, submission
from tests.leaderboard.helpers import expected_ap
from zendar_leaderboard.ground_truth import divide_frames
from zendar_leaderboard.scoring import format_ap_percent
from zendar_leaderboard.store import Store


@pytest.fixture
def browser(tmp_path):
    yield from chromium(tmp_path / "chromium-profile")


@pytest.mark.slow
def test_upload_form_to_ranking_in_chromium(tmp_path, browser):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as until
    from selenium.webdriver.support.ui import WebDriverWait

    gt, gt_path = ground_truth_file(tmp_path)
    db = tmp_path / "board.db"
    store = Store(db)
    token = store.add_team("Radar <Lab>")
    rival_token = store.add_team("Rivals")
    document = submission(gt, seed=7, method="CFAR + SAR <fusion>", uses_camera=True)
    rival = submission(gt, seed=8, method="range-Doppler net")
    path = tmp_path / "predictions.json"
    path.write_text(json.dumps(document))
    public = divide_frames(list(gt["frames"]))[0]
    ap = expected_ap(gt, document, public)

    server = start_server(db, gt_path, "--bootstrap", "200")
    try:
        rival_path = tmp_path / "rival.json"
        rival_path.write_text(json.dumps(rival))
        assert subprocess.run(["zendar-leaderboard", "submit", str(rival_path), "--server", server.url,
                               "--token", rival_token], capture_output=True, timeout=120).returncode == 0

        browser.get(f"{server.url}/submit")
        browser.find_element(By.ID, "token").send_keys(token)
        browser.find_element(By.ID, "file").send_keys(str(path))
        browser.save_screenshot(str(tmp_path / "1-form.png"))
        browser.find_element(By.ID, "send").click()
        WebDriverWait(browser, 120).until(until.text_to_be_present_in_element((By.ID, "status"), "scored"))
        status_text = browser.find_element(By.ID, "status").text
        assert f"AP all {format_ap_percent(ap['all'])}" in status_text  # the API's fraction, shown in percent
        browser.save_screenshot(str(tmp_path / "2-scored.png"))

        browser.find_element(By.ID, "to-ranking").click()
        row = WebDriverWait(browser, 30).until(until.presence_of_element_located((By.CSS_SELECTOR, "tr[id^=entry-]")))
        rows = browser.find_elements(By.CSS_SELECTOR, "#ranking tbody tr")
        assert len(rows) == 2
        ours = next(r for r in rows if "CFAR + SAR <fusion>" in r.text)
        cells = [c.text.split("\n")[0] for c in ours.find_elements(By.CSS_SELECTOR, "td.ap")]
        assert cells == [format_ap_percent(ap[b]) for b in ("near", "mid", "far", "all")]
        assert "Radar <Lab>" in ours.text and "camera" in ours.text
        assert row is not None
        browser.save_screenshot(str(tmp_path / "3-ranking.png"))

        # Sorting by a band puts the better entry of that band first (in both directions of difference).
        rival_ap = expected_ap(gt, rival, public)
        for band in ("near", "mid", "far"):
            if ap[band] == rival_ap[band]:
                continue
            browser.find_element(By.CSS_SELECTOR, f"th button[data-band={band}]").click()
            first = browser.find_elements(By.CSS_SELECTOR, "#ranking tbody tr")[0].text
            assert ("CFAR" in first) == (ap[band] > rival_ap[band]), band

        ours.find_element(By.CSS_SELECTOR, "td.method a").click()
        WebDriverWait(browser, 30).until(until.presence_of_element_located((By.CSS_SELECTOR, "svg")))
        assert "CFAR + SAR <fusion>" in browser.find_element(By.TAG_NAME, "h2").text
        browser.save_screenshot(str(tmp_path / "4-entry.png"))
        assert browser.execute_script("return window.pwned === undefined")
    finally:
        server.stop()

    # The static export, opened from disk.
    out = tmp_path / "site"
    assert subprocess.run(["zendar-leaderboard", "render", "--db", str(db), str(out)], timeout=120).returncode == 0
    browser.get((out / "index.html").as_uri())
    rows = browser.find_elements(By.CSS_SELECTOR, "#ranking tbody tr")
    assert len(rows) == 2 and any("CFAR + SAR <fusion>" in r.text for r in rows)
    browser.save_screenshot(str(tmp_path / "5-static.png"))
    print(f"screenshots in {tmp_path}")
