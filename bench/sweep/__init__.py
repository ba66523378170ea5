"""Stage ``sweep/`` of the harness. Sweep files and presets read into a validated plan: the
sweep's fields, grids expanded to configs, the plan and its file, what can run, the per-
trial random streams, the presets and plugins `bench list` shows.

It may import the top modules of ``bench/``, ``tasks/`` and ``recording/``; never
``results/``, ``run/``, ``report/``, ``cli/`` (docs/architecture.md, 'Layout';
tests/test_layout.py holds it).
"""
