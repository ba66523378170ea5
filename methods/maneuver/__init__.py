"""Maneuver detectors (task ``maneuver-detection``) that test the innovation of a
reference filter (:mod:`.base`): ``innovation``, ``cumulant``, ``wavelet``, ``glr``
and ``cusum``."""
