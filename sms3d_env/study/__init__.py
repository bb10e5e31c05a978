"""The accuracy study: how accurate must a mushroom's estimated pose be for a pick?

| concept | module |
| --- | --- |
| the sweep (orientation x position error x tool x bed size; resumable; processes or Ray), ``sms3d sweep`` / ``sweep-compare`` | :mod:`~sms3d_env.study.sweep` |
| its statistics: Wilson interval, McNemar p, success table, 1-D tolerable error | :mod:`~sms3d_env.study.statistics` |
| figure helpers: atomic PNG saves, figure-path checks, distinct labels, success curves | :mod:`~sms3d_env.study.figures` |
| its report: CSV, 1-D curve, picker curves, summary (``write_report``) | :mod:`~sms3d_env.study.report` |
| the 2-D answer: success map, tolerance region, slices per tool and bed size | :mod:`~sms3d_env.study.success_map` |
"""
