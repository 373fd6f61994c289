"""The ranking and entry pages as people see them: on a phone, after sorting, with long rows, with
a perfect score. Browser checks run the static export in headless Chromium (skipped without it)."""

from __future__ import annotations

import re

import pytest

from tests.leaderboard.chromium import chromium
from tests.leaderboard.adversarial.scored_store import PERFECT_CURVE, add_scored
from zendar_leaderboard import ranking
from zendar_leaderboard.export import render_site
from zendar_leaderboard.store import Store

PHONE_WIDTH_PX = 390
ALL_SENSORS = {"uses_sar": True, "uses_camera": True, "uses_lidar": True, "uses_supervised": True,
               "uses_unsupervised_pretraining": True, "external_data": True}

# all-band order differs from the far-band order, with a tie in far and a band without ground truth.
ROWS = [
    ("Radar Lab", "CFAR + SAR fusion with a long descriptive name", {"near": 0.912, "mid": 0.801, "far": 0.2, "all": 0.7}),
    ("Rivals", "range-Doppler net", {"near": 0.5, "mid": 0.6, "far": 0.65, "all": 0.6}),
    ("Third", "point transformer, tuned for the far band", {"near": 0.3, "mid": 0.4, "far": 0.65, "all": 0.5}),
    ("Fourth", "nothing far", {"near": 0.2, "mid": 0.1, "far": None, "all": 0.1}),
]


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """A static export of ROWS (every sensor flag set, so the Uses column is wide) plus a perfect entry."""
    tmp = tmp_path_factory.mktemp("pages")
    store = Store(tmp / "board.db")
    for team, method, ap in ROWS:
        add_scored(store, store.add_team(team), ap, method=method, runtime_ms=123456.5, **ALL_SENSORS)
    perfect = add_scored(store, store.add_team("Oracle"), {"near": 1.0, "mid": 1.0, "far": 1.0, "all": 1.0},
                         curve=PERFECT_CURVE, method="oracle")
    out = tmp / "site"
    render_site(store, out)
    return out, store, perfect


def envelope_points(entry_html: str) -> list[list[tuple[float, float]]]:
    """The (x, y) points of each chart's dark precision-envelope line."""
    lines = re.findall(r'<polyline[^>]*points="([^"]*)"[^>]*stroke="#0b5cad"', entry_html)
    return [[tuple(map(float, point.split(","))) for point in line.split()] for line in lines]


def test_a_perfect_curve_is_drawn_across_the_chart(site):
    out, _, perfect = site
    charts = envelope_points((out / "entry" / f"{perfect}.html").read_text())
    assert len(charts) == 4
    for points in charts:
        xs = [x for x, _ in points]
        assert max(xs) - min(xs) > 100, points  # from recall 0 to recall 1, not a single point
        assert len({y for _, y in points}) == 1  # flat at precision 1


def test_the_ranking_table_scrolls_in_its_own_box_and_dates_do_not_wrap(site):
    out, _, _ = site
    page = (out / "index.html").read_text()
    assert re.search(r'<div class="table-scroll"><table id="ranking">', page)
    assert re.search(r"td\.date\s*\{[^}]*white-space:\s*nowrap", page)
    assert page.count('<td class="date">') == len(ROWS) + 1


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    yield from chromium(tmp_path_factory.mktemp("chromium-profile"))


def viewport(browser, width_px: int, mobile: bool) -> None:
    browser.execute_cdp_cmd("Emulation.setDeviceMetricsOverride",
                            {"width": width_px, "height": 844, "deviceScaleFactor": 1, "mobile": mobile})


@pytest.mark.slow
def test_on_a_390_px_phone_every_ap_column_is_on_screen(site, browser, tmp_path):
    out, _, _ = site
    viewport(browser, PHONE_WIDTH_PX, mobile=True)
    try:
        browser.get((out / "index.html").as_uri())
        browser.save_screenshot(str(tmp_path / "phone.png"))
        # A page wider than the phone makes the browser lay it out wider (then zoom it out).
        width = browser.execute_script("return window.innerWidth")
        assert width == PHONE_WIDTH_PX, f"laid out {width} px wide on a {PHONE_WIDTH_PX} px phone"
        # The page itself never scrolls sideways.
        assert browser.execute_script("return document.documentElement.scrollWidth") <= width
        boxes = browser.execute_script("""
            return Array.from(document.querySelectorAll('#ranking th button[data-band], #ranking td.ap'))
              .map(function (e) { var r = e.getBoundingClientRect(); return [r.left, r.right]; });""")
        assert len(boxes) == 4 * (len(ROWS) + 2)
        assert all(0 <= left and right <= width for left, right in boxes), boxes
    finally:
        browser.execute_cdp_cmd("Emulation.clearDeviceMetricsOverride", {})


@pytest.mark.slow
def test_sorting_by_a_band_re_ranks_the_number_column(site, browser):
    from selenium.webdriver.common.by import By

    out, store, _ = site
    viewport(browser, 1280, mobile=False)
    browser.get((out / "index.html").as_uri())
    for band in ("far", "near", "all"):
        browser.find_element(By.CSS_SELECTOR, f"th button[data-band={band}]").click()
        shown = [(int(row.get_attribute("id").removeprefix("entry-")), int(row.find_element(By.CSS_SELECTOR, "td").text))
                 for row in browser.find_elements(By.CSS_SELECTOR, "#ranking tbody tr")]
        expected = [(entry["id"], entry["rank"]) for entry in ranking.leaderboard(store, band)["entries"]]
        assert shown == expected, band


@pytest.mark.slow
@pytest.mark.parametrize("width_px", [PHONE_WIDTH_PX * 2, 1024, 1280])
def test_dates_stay_on_one_line(site, browser, width_px):
    out, _, _ = site
    viewport(browser, width_px, mobile=False)
    browser.get((out / "index.html").as_uri())
    lines = browser.execute_script("""
        return Array.from(document.querySelectorAll('#ranking tbody td:last-child')).map(function (cell) {
          var range = document.createRange(); range.selectNodeContents(cell);
          return new Set(Array.from(range.getClientRects()).map(function (r) { return Math.round(r.top); })).size;
        });""")
    assert lines == [1] * (len(ROWS) + 1)


@pytest.mark.slow
def test_a_perfect_curve_is_visible_in_the_browser(site, browser, tmp_path):
    out, _, perfect = site
    viewport(browser, 1280, mobile=False)
    browser.get((out / "entry" / f"{perfect}.html").as_uri())
    browser.save_screenshot(str(tmp_path / "perfect.png"))
    lengths = browser.execute_script("""
        return Array.from(document.querySelectorAll('svg')).map(function (svg) {
          return Math.max.apply(null, Array.from(svg.querySelectorAll('polyline[stroke="#0b5cad"]'))
            .map(function (line) { return line.getTotalLength(); }));
        });""")
    assert len(lengths) == 4 and min(lengths) > 100, lengths
