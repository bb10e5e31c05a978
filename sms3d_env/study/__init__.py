"""The accuracy study: how accurate must a mushroom's estimated pose be for a pick?

| concept | module |
| --- | --- |
| the sweep (orientation x position error x tool x bed size; resumable; processes or Ray), ``sms3d sweep`` / ``sweep-compare`` | :mod:`~sms3d_env.study.sweep` |
| its report: success table, 1-D tolerable error, curves, summary, CSV | :mod:`~sms3d_env.study.report` |
| the 2-D answer: success map, tolerance region, slices per tool and bed size | :mod:`~sms3d_env.study.success_map` |
"""
