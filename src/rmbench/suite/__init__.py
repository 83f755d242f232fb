"""``rmbench table``: the benchmark's tables in one resumable command. For each task, collect
the demonstrations, train every policy and ablation column, evaluate each on the
expert-verified seeds, and write the tables (``tables.py``) beside the published numbers.

``plan.py`` says what a table is and where its files live, ``data_stage.py`` makes a task's
data and ``stages.py`` trains and evaluates one cell (each resumable), ``versions.py`` moves
aside what another task version made, ``job.py`` runs one stage in a worker process,
``schedule.py`` says which jobs run when and on how many slots, ``backends.py`` where (local
processes or Ray), ``progress.py`` draws the grid and ``runner.py`` loops over them;
``cell_rows.py`` and ``tables.py`` read the finished cells into the tables.
"""
