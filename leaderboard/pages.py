"""HTML pages: the ranking, one entry, and the upload form, rendered from Jinja2 templates.

The templates (``templates/*.html``, shipped with the package) are rendered with autoescape: every
value a template prints is HTML-escaped (attributes and text alike, quotes included) unless it is
markup a template made itself. Links are written only for ``http(s)`` URLs, and the server adds a
Content-Security-Policy that runs only the page's own scripts (a per-response nonce), so a method
name cannot become a script. The ranking and entry pages need nothing but themselves (styles and
the sorting script are inside): they work from disk as the static export.

The data they are given carries AP as a fraction in [0, 1] (rounded to 0.001); the pages show it in
percent with one decimal, formatted only at render time (the ``percent`` filter,
:func:`zendar_leaderboard.scoring.format_ap_percent`).
"""

from __future__ import annotations

import html
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jinja2
from markupsafe import Markup

from zendar_dataset.eval.protocol import ALL_BAND, BANDS_M, MATCH_DISTANCE_M
from zendar_leaderboard.scoring import BANDS, format_ap_percent

TITLE = "Zendar radar benchmark: moving-car detection"

#: The meta flags shown as tags, with their labels.
SENSOR_TAGS = (
    ("uses_sar", "SAR"), ("uses_camera", "camera"), ("uses_lidar", "lidar"),
    ("uses_supervised", "supervised"), ("uses_unsupervised_pretraining", "unsup. pretraining"),
    ("external_data", "external data"),
)


def _escaped(value: Any) -> Markup:
    # Applied to every printed value before autoescape sees it: html.escape writes &quot; and &#x27;
    # (markupsafe would write &#34; and &#39;), so the pages keep the entities they always had. None
    # prints as nothing; markup made by a template passes unchanged.
    if hasattr(value, "__html__"):
        return Markup(value)
    return Markup(html.escape("" if value is None else str(value), quote=True))


_templates = jinja2.Environment(
    loader=jinja2.FileSystemLoader(Path(__file__).with_name("templates")),
    autoescape=True,
    finalize=_escaped,
    undefined=jinja2.StrictUndefined,
    trim_blocks=True,
    lstrip_blocks=True,
    keep_trailing_newline=True,
)
_templates.filters["percent"] = format_ap_percent
_templates.globals.update(
    site_title=TITLE, bands=BANDS, all_band=ALL_BAND, band_ranges_m=BANDS_M, match_distance_m=MATCH_DISTANCE_M,
    sensor_labels=SENSOR_TAGS, zip=zip,
)


def ranking_page(
    board: dict[str, Any], *, entry_href: Callable[[int], str], static: bool, nonce: str | None = None
) -> str:
    """The ranking as HTML (sortable by each band; intervals under the AP when known).

    Parameters
    ----------
    board
        :func:`zendar_leaderboard.ranking.leaderboard`.
    entry_href
        The link to an entry's page, from its id.
    static
        Links for the static export (relative, no upload form) rather than the server.
    nonce
        The Content-Security-Policy nonce of the styles and script (none for the static export).
    """
    return _templates.get_template("ranking.html").render(
        board=board, entry_href=entry_href, static=static, nonce=nonce, root=""
    )


def entry_page(
    entry: dict[str, Any], parts: dict[str, dict | None], *, static: bool, nonce: str | None = None, root: str = ""
) -> str:
    """One entry: its scores per shown part, PR curves and meta.

    ``entry`` and ``parts`` are :func:`zendar_leaderboard.ranking.entry_parts`; ``root`` leads from
    the page to the static export's top folder.
    """
    return _templates.get_template("entry.html").render(entry=entry, parts=parts, static=static, nonce=nonce, root=root)


def submit_page(*, quota: int, max_bytes: int, nonce: str | None = None) -> str:
    """The upload form for people (the API does the work; see docs/leaderboard.md)."""
    return _templates.get_template("submit.html").render(
        quota=quota, max_bytes=max_bytes, static=False, nonce=nonce, root=""
    )
