"""Models: the radar and filtering maths shared by methods and scenarios.

A scenario uses a model to generate data, a method the same model to process
it; keeping the model here lets neither import the other, and keeps the
harness (:mod:`bench`) free of domain maths. Modules:

* :mod:`models.kalman` — the batched linear Kalman filter and its innovations
  (with the per-trial filterpy loop as oracle); :class:`~models.kalman.LinearGaussianFilter`,
  the reference filter a detection scene carries;
* :mod:`models.glint` — glint measurement-noise densities (Gaussian core plus
  Laplace spikes); :class:`~models.glint.GlintModel`, the tracking model a
  ``glint`` tracking scene carries;
* :mod:`models.spherical` — range / bearing / elevation measurements of a
  Cartesian position, Jacobian and angle-aware residual;
* :mod:`models.ar_noise` — autoregressive noise: stationarity, autocovariance,
  exact predictors.

The models a scenario hands to methods are frozen dataclasses with typed,
documented fields, validated when built (docs/architecture.md, 'Scenes').
Models import neither :mod:`methods` nor :mod:`scenarios`; of the harness, only its public field checks (:mod:`bench.core`).
"""

if not __name__.startswith("radarbench."):   # imported by its old name from a checkout: the new package
    from radarbench import _compat           # instead, with a deprecation warning (radarbench/_compat.py)
    _compat.replace_old_package(__name__)


from radarbench import bench  # noqa: E402,F401 - the portable target (bench/__init__.py) before numpy or numba is imported
