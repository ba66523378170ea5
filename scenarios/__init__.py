"""Scenarios: one module per scenario family; each registers its scenarios
with :func:`bench.registry.register_scenario`. Scenarios import the harness's
API (:mod:`bench`) and the shared maths (:mod:`models`), never a method."""

import bench  # noqa: E402,F401 - the portable target (bench/__init__.py) before numpy or numba is imported
