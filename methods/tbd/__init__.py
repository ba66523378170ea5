"""Track-before-detect (task ``tbd``): ``dp-tbd`` and ``dp-tbd-mf`` (:mod:`.dp_tbd`),
``pf-tbd`` (:mod:`.pf_tbd`); their numba kernels (:mod:`.kernels`, :mod:`.mf_kernels`,
:mod:`.pf_kernels`), the along-track likelihood's kernel (:mod:`.alongtrack`) and the
plain NumPy recursions the tests and ``bench perf`` compare them with (:mod:`.reference`)."""
