"""``rmbench table``: the benchmark's tables in one resumable command. For each task, collect
the demonstrations, train every policy and ablation column, evaluate each on the
expert-verified seeds, and write the tables (``tables.py``) beside the published numbers.

``plan.py`` says what a table is and where its files live, ``stages.py`` runs one stage of
one cell (each resumable), ``job.py`` one stage in a worker process, ``runner.py`` the jobs
in dependency order on local processes or Ray with a progress grid.
"""
