"""The accuracy study: how accurate must a mushroom's estimated pose be for a pick?

| concept | module |
| --- | --- |
| what a sweep runs: its settings (``SweepConfig``), physics variants and tasks (orientation x position error x robot x tool x bed size x target rule) | :mod:`~sms3d_env.study.plan` |
| running it: one task's episodes, the process pool or Ray (``run_sweep``) | :mod:`~sms3d_env.study.sweep` |
| its folder: recorded settings, the resume-or-refuse check, reading parts back (``load_rows``) | :mod:`~sms3d_env.study.resume` |
| pickers side by side on the same episodes (paired McNemar table) | :mod:`~sms3d_env.study.compare` |
| ``sms3d sweep`` / ``sweep-compare`` | :mod:`~sms3d_env.study.cli` |
| its statistics: Wilson interval, McNemar p, success table, 1-D tolerable error | :mod:`~sms3d_env.study.statistics` |
| figure helpers: atomic PNG saves, figure-path checks, distinct labels, success curves | :mod:`~sms3d_env.study.figures` |
| its report: CSV, 1-D curve, picker curves, summary (``write_report``) | :mod:`~sms3d_env.study.report` |
| the 2-D answer: success map, tolerance region, slices per tool and bed size | :mod:`~sms3d_env.study.success_map` |
"""
