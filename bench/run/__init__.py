"""Stage ``run/`` of the harness. The plan executed: units of work, the driver that hands them
to an executor (process pool or Dask) and stores each as it finishes, the forkserver and its
workers, the warm-up of the kernels and numba's cache, the identities that decide what must
run again, progress on stderr.

It may import the top modules of ``bench/``, ``tasks/`` and ``recording/``, and the stages
``sweep/``, ``results/``; never ``report/``, ``cli/`` (docs/architecture.md, 'Layout';
tests/test_layout.py holds it).
"""
