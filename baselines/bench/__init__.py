"""``zendar-bench``: Table 1 end to end — its command line, the run (steps cached in a run directory
under keys of their inputs), the shared test scenes for scoring, the configurations, the results
table and claims, the figures, and ``verify``.

Modules: ``cli`` (its console script is ``zendar_baselines.entry``), ``run`` (the run and its outputs), ``context``
(the frozen record of one run), ``steps`` (split, automatic labels, label masks, training of a row),
``scoring`` (the CFAR and CNN predictions on the test split), ``run_directory``, ``configs``,
``results_table``, ``figures``, ``verify``. Kept light: importing it loads no numerical library.
"""
