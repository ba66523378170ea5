"""Trackers of the ``glint`` scenario's spherical measurements (task ``tracking``):
``ekf`` (:mod:`.ekf`) and the block Viterbi estimator ``viterbi`` (:mod:`.viterbi`; its
trellis in :mod:`.trellis`, the paper's 1-D trellis in :mod:`.viterbi_paper1d`)."""
