"""Methods: one folder per method family (``maneuver``, ``kinematic``, ``glint``, ``tbd``,
``cfar``, ``multitarget``; docs/architecture.md, 'Layout'); each module registers its
methods with :func:`bench.registry.register_method`, the family's helper modules register
nothing. Discovery imports every module of every family (a name starting with ``_`` is left
out). Methods import the harness's API (:mod:`bench`) and the shared maths
(:mod:`models`), never a scenario."""

if not __name__.startswith("radarbench."):   # imported by its old name from a checkout: the new package
    from radarbench import _compat           # instead, with a deprecation warning (radarbench/_compat.py)
    _compat.replace_old_package(__name__)


from radarbench import bench  # noqa: E402,F401 - the portable target (bench/__init__.py) before numpy or numba is imported
