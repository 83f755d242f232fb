"""rmbench inside LeRobot (``pip install 'rmbench[lerobot]'`` into a LeRobot environment).

- ``env.py``: each task as a gym env in LeRobot's evaluation layout (ids
  ``rmbench_lerobot/<task>``): LeRobot's episode seed k runs rmbench's k-th expert-verified
  evaluation seed, the task description is the episode's instruction, and ``is_success`` is
  the task's. Imports no LeRobot.
- ``config.py``: the ``rmbench`` ``EnvConfig`` (``lerobot-eval --env.type=rmbench``), which
  LeRobot loads with ``--env.discover_packages_path=rmbench.lerobot``.
- ``policy.py``: the ``lerobot:PATH`` policy spec, a LeRobot checkpoint evaluated by
  ``rmbench eval`` beside rmbench's own policies.

Only ``config.py`` and the factory in ``policy.py`` import LeRobot; rmbench's core never
imports this package.
"""
