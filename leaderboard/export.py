"""Static export: ``index.html``, ``leaderboard.json``, ``leaderboard.csv`` and ``entry/ID.html``.

The files need no server: styles and the sorting script are inside the pages, links are relative,
so the folder works opened from disk or from any static host. Each file is written to a temporary
name and renamed, and only these names are written inside OUT.
"""

from __future__ import annotations

import os
from pathlib import Path

import orjson

from zendar_dataset.atomic_files import write_bytes_atomic
from zendar_dataset.errors import ZendarError
from zendar_leaderboard import ranking
from zendar_leaderboard.pages import entry_page, ranking_page
from zendar_leaderboard.store import Store


# A published site is read by a web server running as another user, whatever the publisher's umask.
PUBLISHED_MODE = 0o644


def render_site(store: Store, out: str | os.PathLike) -> list[Path]:
    """Write the static leaderboard into ``out`` (created if missing).

    Returns
    -------
    list of Path
        The files written.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ZendarError(f"output {str(out)!r} exists and is not a folder")
    (out / "entry").mkdir(parents=True, exist_ok=True)
    board = ranking.leaderboard(store)
    written = []
    for entry in board["entries"]:
        found = ranking.entry_parts(store, entry["id"])
        if found is None:  # hidden or deleted since the ranking was read
            continue
        page = entry_page(*found, static=True, root="../")
        path = out / "entry" / f"{entry['id']}.html"
        write_bytes_atomic(path, page.encode(), mode=PUBLISHED_MODE)
        written.append(path)
    files = {
        "leaderboard.json": orjson.dumps(board, option=orjson.OPT_INDENT_2),
        "leaderboard.csv": ranking.to_csv(board).encode(),
        "index.html": ranking_page(board, entry_href=lambda i: f"entry/{i}.html", static=True).encode(),
    }
    for name, data in files.items():
        write_bytes_atomic(out / name, data, mode=PUBLISHED_MODE)
        written.append(out / name)
    return written
