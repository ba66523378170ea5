"""Kinematic trackers (task ``tracking``): ``cv-kf``, ``ca-kf``, ``singer``
(:mod:`.kinematic_kf`), ``imm-cv-ca``, ``current-statistical``, ``vd-filter`` on their
common base (:mod:`.base`), and ``ar-adaptive`` (:mod:`.ar_adaptive`)."""
