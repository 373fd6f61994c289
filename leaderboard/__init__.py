"""The Zendar leaderboard: submissions scored by the official evaluator against a hidden test split.

Installed as ``zendar_leaderboard`` (the repository folder is ``leaderboard/``). Modules:

- ``ground_truth`` — the hidden test split, its checksum and its public / private parts;
- ``names`` — what a shown name or text may contain, the normal form of names, look-alike team names;
- ``meta`` and ``submission`` — the submission rules (the evaluator's validator plus ``meta``);
- ``scoring`` — per-part scores through ``zendar_dataset.eval.evaluate``, rounded for display;
- ``store`` — SQLite (WAL) records of teams, submissions and scores;
- ``worker`` and ``scheduler`` — the scorer process, its limits and the watchdog;
- ``ranking`` — the ranking as data: which entries are shown, which part of their score, in what
  order, and as CSV;
- ``pages`` — the HTML pages, rendered from the Jinja2 templates in ``templates/``;
- ``export`` — the static site (ranking, pages; no server);
- ``routes`` and ``server`` — the HTTP API's route table and views; the server, its settings and
  its ranking cache;
- ``client`` and ``cli`` — ``zendar-leaderboard``.

See docs/leaderboard.md.
"""

from __future__ import annotations

__all__: list[str] = []
