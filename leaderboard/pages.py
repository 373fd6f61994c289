"""HTML pages: the ranking, one entry, and the upload form.

Every value that came from a submission passes through ``html.escape`` (attributes and text alike),
links are written only for ``http(s)`` URLs, and the server adds a Content-Security-Policy that runs
only the page's own scripts (a per-response nonce), so a method name cannot become a script. The
ranking and entry pages need nothing but themselves: they work from disk as the static export.

The data they are given carries AP as a fraction in [0, 1] (rounded to 0.001); the pages show it in
percent with one decimal, formatted only here at render time (:func:`fmt_ap`).
"""

from __future__ import annotations

import html
from collections.abc import Callable
from typing import Any

from zendar_dataset.eval.protocol import ALL_BAND, BANDS_M, MATCH_DISTANCE_M
from zendar_leaderboard.scoring import BANDS, format_ap_percent

TITLE = "Zendar radar benchmark: moving-car detection"

_CSS = """
:root { --ink: #1b1f24; --muted: #5b6470; --line: #d8dde3; --accent: #0b5cad; --band: #f3f6f9; }
* { box-sizing: border-box; }
body { font: 15px/1.45 system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; color: var(--ink);
       margin: 0; background: #fff; }
header { background: #102a43; color: #fff; padding: 18px 32px; }
header h1 { margin: 0; font-size: 22px; font-weight: 600; }
header p { margin: 4px 0 0; color: #bcccdc; font-size: 14px; }
nav { display: flex; gap: 18px; padding: 10px 32px; border-bottom: 1px solid var(--line); background: var(--band); }
nav a { color: var(--accent); text-decoration: none; font-weight: 500; }
main { padding: 20px 32px 40px; max-width: 1200px; }
.note { color: var(--muted); font-size: 14px; margin: 0 0 14px; }
table { border-collapse: collapse; width: 100%; }
th, td { padding: 8px 10px; border-bottom: 1px solid var(--line); text-align: left; vertical-align: top; }
th { font-size: 13px; color: var(--muted); font-weight: 600; white-space: nowrap; }
td.num, th.num { text-align: right; font-variant-numeric: tabular-nums; }
td.ap { font-weight: 600; font-size: 16px; }
td.ap small { display: block; font-weight: 400; font-size: 12px; color: var(--muted); }
tbody tr:nth-child(even) { background: #fafbfc; }
th button { font: inherit; color: inherit; background: none; border: 0; padding: 0; cursor: pointer; }
th button[aria-pressed="true"] { color: var(--accent); text-decoration: underline; }
.tag { display: inline-block; font-size: 11px; padding: 1px 6px; margin: 0 3px 3px 0; border-radius: 8px;
       background: #e6eef7; color: #234; }
.method a { color: var(--accent); font-weight: 600; text-decoration: none; }
.method .team { color: var(--muted); font-size: 13px; }
.empty { padding: 24px; text-align: center; color: var(--muted); background: var(--band); }
.charts { display: flex; flex-wrap: wrap; gap: 16px; margin: 10px 0 20px; }
.charts figure { margin: 0; }
.charts figcaption { font-size: 13px; color: var(--muted); text-align: center; }
dl.meta { display: grid; grid-template-columns: max-content 1fr; gap: 4px 16px; }
dl.meta dt { color: var(--muted); }
dl.meta dd { margin: 0; overflow-wrap: anywhere; white-space: pre-wrap; }
form.upload { display: grid; grid-template-columns: max-content minmax(0, 420px); gap: 12px 16px; align-items: center;
              padding: 18px; border: 1px solid var(--line); border-radius: 8px; background: var(--band); }
form.upload input[type=password], form.upload input[type=file] { font: inherit; width: 100%; }
form.upload button { grid-column: 2; justify-self: start; font: inherit; font-weight: 600; padding: 8px 20px;
                     background: var(--accent); color: #fff; border: 0; border-radius: 6px; cursor: pointer; }
#status { margin-top: 18px; font-size: 15px; }
#status.failed { color: #a61b1b; }
#status ul { color: #a61b1b; }
code { font-size: 13px; }
table.scores { width: auto; min-width: 200px; }
.part { display: flex; flex-wrap: wrap; gap: 24px; align-items: flex-start; }
.charts { margin-top: 0; }
"""

# Sorting in the browser: each AP header re-orders the rows by its band (descending, empty last);
# the rows carry the AP fractions of the JSON in data-ap* attributes.
_SORT_JS = """
document.querySelectorAll('th button[data-band]').forEach(function (button) {
  button.addEventListener('click', function (event) {
    event.preventDefault();
    var band = button.dataset.band, body = document.querySelector('#ranking tbody');
    var rows = Array.prototype.slice.call(body.rows);
    rows.sort(function (a, b) {
      var x = a.dataset['ap' + band], y = b.dataset['ap' + band];
      if (x === '' && y === '') return 0; if (x === '') return 1; if (y === '') return -1;
      return parseFloat(y) - parseFloat(x);
    });
    rows.forEach(function (row) { body.appendChild(row); });
    document.querySelectorAll('th button[data-band]').forEach(function (b) {
      b.setAttribute('aria-pressed', b === button ? 'true' : 'false');
    });
  });
});
"""

_SUBMIT_JS = """
var form = document.getElementById('upload'), statusBox = document.getElementById('status');
// The API answers AP as a fraction rounded to 0.001: shown in percent with one decimal.
function ap(v) { return v === null || v === undefined ? 'n/a' : (100 * v).toFixed(1); }
function say(text, failed) { statusBox.textContent = text; statusBox.className = failed ? 'failed' : ''; }
function poll(id, token) {
  fetch('/api/submissions/' + id, {headers: {'Authorization': 'Bearer ' + token}})
    .then(function (r) { return r.json(); })
    .then(function (s) {
      if (s.status === 'scored') {
        say('Submission ' + id + ' scored: AP all ' + ap(s.ap.all) + ' (near ' + ap(s.ap.near) +
            ', mid ' + ap(s.ap.mid) + ', far ' + ap(s.ap.far) + ').');
        var link = document.createElement('a'); link.href = '/'; link.id = 'to-ranking';
        link.textContent = ' See the ranking.'; statusBox.appendChild(link);
      } else if (s.status === 'failed') {
        say('Submission ' + id + ' failed: ' + s.error, true);
      } else {
        say('Submission ' + id + ': ' + s.status + (s.position ? ' (position ' + s.position + ' in the queue)' : '') + '\\u2026');
        setTimeout(function () { poll(id, token); }, 1000);
      }
    });
}
form.addEventListener('submit', function (event) {
  event.preventDefault();
  var token = document.getElementById('token').value.trim(), file = document.getElementById('file').files[0];
  if (!file) { say('Choose a predictions file first.', true); return; }
  say('Uploading ' + file.name + '\\u2026');
  fetch('/api/submissions', {method: 'POST', body: file,
        headers: {'Authorization': 'Bearer ' + token, 'Content-Type': 'application/json'}})
    .then(function (r) { return r.json().then(function (body) { return [r.status, body]; }); })
    .then(function (answer) {
      var status = answer[0], body = answer[1];
      if (status === 202) { poll(body.id, token); return; }
      say(body.error || ('refused (' + status + ')'), true);
      if (body.problems) {
        var list = document.createElement('ul');
        body.problems.forEach(function (p) { var li = document.createElement('li'); li.textContent = p; list.appendChild(li); });
        statusBox.appendChild(list);
      }
    })
    .catch(function (error) { say('Upload failed: ' + error, true); });
});
"""


def esc(value: Any) -> str:
    """Text or attribute content, escaped (quotes included)."""
    return html.escape("" if value is None else str(value), quote=True)


def fmt_ap(value: float | None) -> str:
    """An AP fraction (or None) as shown on the pages: percent with one decimal, "–" without ground truth."""
    return format_ap_percent(value)


def fmt_ci(interval: list[float] | None) -> str:
    """A bootstrap interval of AP fractions as shown under an AP: ``[low, high]`` in percent."""
    return f"<small>[{fmt_ap(interval[0])}, {fmt_ap(interval[1])}]</small>" if interval else ""


def _page(title: str, body: str, *, nonce: str | None, static: bool, script: str = "", root: str = "") -> str:
    # Static pages link relatively (``root`` leads from the page to the export's top folder).
    nonce_attr = f' nonce="{esc(nonce)}"' if nonce else ""
    prefix = root if static else "/"
    links = [f'<a href="{root}index.html">Ranking</a>' if static else '<a href="/">Ranking</a>']
    if not static:
        links.append('<a href="/submit">Submit</a>')
    links.append(f'<a href="{prefix}leaderboard.json">JSON</a>')
    links.append(f'<a href="{prefix}leaderboard.csv">CSV</a>')
    bands = ", ".join(f"{name} [{lo:g}, {hi:g}) m" for name, (lo, hi) in BANDS_M.items())
    return (
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
        f"<title>{esc(title)}</title><style{nonce_attr}>{_CSS}</style></head><body>"
        f"<header><h1>{esc(TITLE)}</h1><p>Average precision (%) of moving-car centres within "
        f"{MATCH_DISTANCE_M:g} m, per range band: {esc(bands)}.</p></header>"
        f"<nav>{''.join(links)}</nav><main>{body}</main>"
        + (f"<script{nonce_attr}>{script}</script>" if script else "")
        + "</body></html>\n"
    )


def _sensor_tags(meta: dict) -> str:
    names = [
        ("uses_sar", "SAR"), ("uses_camera", "camera"), ("uses_lidar", "lidar"),
        ("uses_supervised", "supervised"), ("uses_unsupervised_pretraining", "unsup. pretraining"),
        ("external_data", "external data"),
    ]
    return "".join(f'<span class="tag">{esc(label)}</span>' for key, label in names if meta.get(key) is True)


def ranking_page(
    board: dict[str, Any], *, entry_href: Callable[[int], str], static: bool, nonce: str | None = None
) -> str:
    """The ranking as HTML (sortable by each band; intervals under the AP when known)."""
    closed = board["round"]["closed"]
    sorted_by = board.get("sorted_by", ALL_BAND)
    if closed:
        note = ("The round is closed: entries are ranked by the <b>private</b> part of the test split; "
                "the public part's AP is shown in brackets.")
    else:
        note = ("Live scores on the <b>public</b> part of the test split. The private part decides the final "
                "ranking and is shown when the round closes.")
    note += (" AP in percent, rounded to 0.1; 95% bootstrap interval over scenes underneath when available."
             " Click an AP heading to rank by that band.")
    header = "".join(
        f'<th class="num"><button type="button" data-band="{band}" aria-pressed="{str(band == sorted_by).lower()}">'
        f"AP {band}</button></th>"
        for band in BANDS
    )
    rows = []
    for entry in board["entries"]:
        data = "".join(
            f' data-ap{band}="{"" if entry["ap"].get(band) is None else entry["ap"][band]}"' for band in BANDS
        )
        cells = []
        for band in BANDS:
            ci = (entry.get("ci") or {}).get(band)
            extra = fmt_ci(ci)
            if closed and entry.get("ap_public"):
                extra += f"<small>public {fmt_ap(entry['ap_public'].get(band))}</small>"
            cells.append(f'<td class="num ap">{fmt_ap(entry["ap"].get(band))}{extra}</td>')
        meta = entry["meta"]
        rows.append(
            f'<tr id="entry-{entry["id"]}"{data}><td class="num">{entry["rank"]}</td>'
            f'<td class="method"><a href="{esc(entry_href(entry["id"]))}">{esc(entry["method"])}</a>'
            f'<div class="team">{esc(entry["team"])}</div></td>'
            + "".join(cells)
            + f"<td>{_sensor_tags(meta)}</td>"
            f'<td class="num">{esc(meta.get("runtime_ms"))}</td>'
            f'<td>{esc(entry["submitted_at"][:10])}</td></tr>'
        )
    table = (
        '<table id="ranking"><thead><tr><th class="num">#</th><th>Method / team</th>'
        f'{header}<th>Uses</th><th class="num">ms / frame</th><th>Submitted</th></tr></thead>'
        f"<tbody>{''.join(rows)}</tbody></table>"
    )
    if not rows:
        table += '<p class="empty">No scored submissions yet.</p>'
    body = f'<p class="note">{note}</p>{table}'
    return _page(TITLE, body, nonce=nonce, static=static, script=_SORT_JS)


def _pr_svg(curve: dict[str, list[float]], band: str) -> str:
    size, pad = 210, 32
    inner = size - 2 * pad

    def xy(recall: float, precision: float) -> str:
        return f"{pad + recall * inner:.1f},{pad + (1 - precision) * inner:.1f}"

    envelope = " ".join(xy(r, p) for r, p in zip(curve["recall"], curve["precision_envelope"]))
    measured = " ".join(xy(r, p) for r, p in zip(curve["recall"], curve["precision"]))
    grid = "".join(
        f'<line x1="{pad}" y1="{pad + t * inner}" x2="{pad + inner}" y2="{pad + t * inner}" stroke="#e3e7eb"/>'
        f'<line x1="{pad + t * inner}" y1="{pad}" x2="{pad + t * inner}" y2="{pad + inner}" stroke="#e3e7eb"/>'
        for t in (0, 0.25, 0.5, 0.75, 1)
    )
    ticks = "".join(
        f'<text x="{pad + t * inner}" y="{pad + inner + 12}" font-size="10" text-anchor="middle" fill="#5b6470">{t:g}</text>'
        f'<text x="{pad - 4}" y="{pad + (1 - t) * inner + 3}" font-size="10" text-anchor="end" fill="#5b6470">{t:g}</text>'
        for t in (0, 0.5, 1)
    )
    return (
        f'<svg width="{size}" height="{size}" viewBox="0 0 {size} {size}" role="img" '
        f'aria-label="precision-recall curve, band {esc(band)}">{grid}{ticks}'
        f'<polyline points="{measured}" fill="none" stroke="#9fb3c8" stroke-width="1"/>'
        f'<polyline points="{envelope}" fill="none" stroke="#0b5cad" stroke-width="2"/>'
        f'<text x="{size / 2}" y="{size - 6}" font-size="11" text-anchor="middle" fill="#5b6470">recall</text>'
        f'<text x="10" y="{size / 2}" font-size="11" text-anchor="middle" fill="#5b6470" '
        f'transform="rotate(-90 10 {size / 2})">precision</text></svg>'
    )


def entry_page(
    entry: dict[str, Any], parts: dict[str, dict | None], *, static: bool, nonce: str | None = None, root: str = ""
) -> str:
    """One entry: its scores per shown part, PR curves and meta."""
    sections = []
    for part, score in parts.items():
        if not score:
            continue
        ci = score.get("ci") or {}
        rows = "".join(
            f"<tr><td>{band}</td><td class=\"num ap\">{fmt_ap(score['ap'][band])}"
            + fmt_ci(ci.get(band))
            + "</td></tr>"
            for band in BANDS
        )
        charts = "".join(
            f"<figure>{_pr_svg(score['pr_curves'][band], band)}<figcaption>{band}: AP {fmt_ap(score['ap'][band])}"
            "</figcaption></figure>"
            for band in BANDS
            if score["pr_curves"][band]["recall"]
        )
        sections.append(
            f"<h3>{esc(part.capitalize())} part ({score['n_frames']} frames)</h3>"
            f'<div class="part"><table class="scores"><thead><tr><th>band</th><th class="num">AP [%]</th></tr></thead>'
            f'<tbody>{rows}</tbody></table><div class="charts">{charts}</div></div>'
        )
    meta = entry["meta"]
    url = meta.get("url")
    url_html = "–"
    if url and url.startswith(("http://", "https://")):
        url_html = f'<a href="{esc(url)}" rel="nofollow noopener">{esc(url)}</a>'
    items = [
        ("Team", esc(entry["team"])), ("Description", esc(meta.get("description"))), ("Link", url_html),
        ("Hardware", esc(meta.get("hardware"))),
        ("Runtime", f"{esc(meta.get('runtime_ms'))} ms per frame"), ("Uses", _sensor_tags(meta) or "radar only"),
        ("Submitted", esc(entry["submitted_at"])),
        ("Submission SHA-256", f"<code>{esc(entry['submission_sha256'])}</code>"),
        ("Protocol", f"version {esc(entry['protocol_version'])}, evaluator {esc(entry['evaluator_version'])}"),
        ("Labels SHA-256", f"<code>{esc(entry['gt_sha256'])}</code>"),
    ]
    meta_html = "".join(f"<dt>{name}</dt><dd>{value}</dd>" for name, value in items)
    body = (
        f"<h2>{esc(entry['method'])}</h2>{''.join(sections)}"
        '<p class="note">Dark line: the precision envelope the AP integrates; light line: measured precision.</p>'
        f'<h3>About the method</h3><dl class="meta">{meta_html}</dl>'
    )
    return _page(f"{entry['method']} – {TITLE}", body, nonce=nonce, static=static, root=root)


def submit_page(*, quota: int, max_bytes: int, nonce: str | None = None) -> str:
    """The upload form for people (the API does the work; see docs/leaderboard.md)."""
    body = (
        "<h2>Submit predictions</h2>"
        f'<p class="note">Upload a predictions file with a complete <code>meta</code> object '
        f"(check it first with <code>zendar-leaderboard check FILE</code>). At most {quota} scored submissions per "
        f"team in any 30 days; files up to {max_bytes / 1e6:g} MB. Your team's token was given to you by the "
        "organisers.</p>"
        '<form class="upload" id="upload">'
        '<label for="token">Team token</label><input type="password" id="token" name="token" autocomplete="off" required>'
        '<label for="file">Predictions (.json)</label>'
        '<input type="file" id="file" name="file" accept=".json,application/json" required>'
        '<button type="submit" id="send">Submit</button></form>'
        '<div id="status" role="status" aria-live="polite"></div>'
    )
    return _page(f"Submit – {TITLE}", body, nonce=nonce, static=False, script=_SUBMIT_JS)
