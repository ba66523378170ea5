"""Stage ``results/`` of the harness. What a run keeps: the run folder (lock, manifest, whole-
file writes), its SQLite store, the CSVs, the provenance of each result, the failures
located in a plugin's code, and a run's tables read back as tidy frames.

It may import the top modules of ``bench/``, ``tasks/`` and ``recording/``, and the stages
``sweep/``; never ``run/``, ``report/``, ``cli/`` (docs/architecture.md, 'Layout';
tests/test_layout.py holds it).
"""
