"""CFAR detection (task ``cell-detection``): ``ca-cfar``, ``os-cfar``, ``go-cfar``,
``so-cfar``, ``regression-cfar`` and ``region-adaptive`` (:mod:`.detectors`, on the maths
of :mod:`models.cfar`) and their straightforward implementations (:mod:`.reference`)."""
