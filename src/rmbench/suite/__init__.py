"""``rmbench table``: the benchmark's tables in one resumable command. For each task, collect
the demonstrations, train every policy and ablation column, evaluate each on the
expert-verified seeds, and write the tables (``tables.py``) beside the published numbers.

``plan.py`` says what a table is and where its files live, ``stages.py`` runs one stage of
one cell (each resumable), ``job.py`` one stage in a worker process, ``schedule.py`` which
jobs run when and on how many slots, ``backends.py`` where (local processes or Ray),
``progress.py`` the grid, and ``runner.py`` the loop over them.
"""
