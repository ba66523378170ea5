"""Methods: one module per method family; each registers its methods with
:func:`bench.registry.register_method`. Modules whose name starts with ``_``
are helpers and are not imported by discovery. Methods import the harness's
API (:mod:`bench`) and the shared maths (:mod:`models`), never a scenario."""

import bench  # noqa: E402,F401 - the portable target (bench/__init__.py) before numpy or numba is imported
