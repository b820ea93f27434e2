"""``motok-robot sweep``: validation campaigns over prompts x seeds x robots x settings, on Ray.

One module per idea:

* :mod:`~motok_robot.sweep.spec` reads the TOML spec into :class:`~motok_robot.sweep.spec.Cell` s;
* :mod:`~motok_robot.sweep.run_options` turns a variant's ``run`` options into the
  :class:`~motok_robot.pipeline.PipelineConfig` and the ``Pipeline.run`` arguments of a cell;
* :mod:`~motok_robot.sweep.inputs` hashes what a cell reads (``--resume`` compares it);
* :mod:`~motok_robot.sweep.worker` runs one cell on a kept :class:`~motok_robot.pipeline.Pipeline`;
* :mod:`~motok_robot.sweep.engine` schedules the cells: in process, or on Ray actors;
* :mod:`~motok_robot.sweep.results` writes the rows (journal, Parquet, CSV) and the cell folders;
* :mod:`~motok_robot.sweep.summary` writes ``summary.md`` and the heatmaps;
* :mod:`~motok_robot.sweep.driver` ties them together (:func:`~motok_robot.sweep.driver.run_sweep`).

Nothing here imports Ray, pyarrow, torch or MuJoCo at import time (docs/sweep.md).
"""
