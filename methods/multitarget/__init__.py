"""Multi-target tracking (task ``multi-target``): ``jpda-ukf`` and ``gnn-ekf``
(:mod:`.trackers`), their compiled scan loop (:mod:`.kernels`), JPDA marginals
(:mod:`.jpda`) and M/N track management (:mod:`.track_management`); the Stone Soup
peers ``stonesoup-jpda`` (:mod:`.stonesoup_peer`), ``stonesoup-gmphd`` and
``stonesoup-mfa`` (optional: the ``peers`` extra)."""
