"""Scenarios: one module per scenario family; each registers its scenarios
with :func:`bench.registry.register_scenario`. Scenarios import the harness's
API (:mod:`bench`) and the shared maths (:mod:`models`), never a method."""

if not __name__.startswith("radarbench."):   # imported by its old name from a checkout: the new package
    from radarbench import _compat           # instead, with a deprecation warning (radarbench/_compat.py)
    _compat.replace_old_package(__name__)


from radarbench import bench  # noqa: E402,F401 - the portable target (bench/__init__.py) before numpy or numba is imported
