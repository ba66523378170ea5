"""A tests-only multi-target "tracker" that knows the truth: each present target
gets a track at its true position plus Gaussian noise (tentative for its first
``delay_scans`` scans, confirmed after, terminated at the scan it leaves), and
``false_slots`` slots hold deliberately false confirmed tracks in blocks of
``false_life_scans`` scans with probability ``false_probability`` each. It
exercises the task's metrics, report and recording end to end; it is not a
method of the benchmark (registered by the tests that use it)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from radarbench.bench.core import Method
from radarbench.bench.params import param
from radarbench.bench.tasks.multitarget import MULTI_TARGET, MultiTargetOutput


def _run_starts(present: np.ndarray) -> np.ndarray:
    """(n, K, T) the first scan of the current presence run (-1 where absent)."""
    K = present.shape[1]
    begins = present & ~np.concatenate([np.zeros_like(present[:, :1]), present[:, :-1]], axis=1)
    start = np.maximum.accumulate(np.where(begins, np.arange(K)[None, :, None], -1), axis=1)
    return np.where(present, start, -1)


class OracleTracker(Method):
    """Truth plus noise, with deliberately false tracks (tests only)."""

    name = "mtt-oracle"
    task = MULTI_TARGET

    @dataclass(frozen=True)
    class Params:
        position_noise_m: float = param(200.0, "std of the noise added to the true positions (m)", ge=0.0,
                                        le=1e5, why="test values")
        delay_scans: int = param(2, "scans a new track stays tentative", ge=0, le=100, why="test values")
        false_slots: int = param(2, "slots that may hold a false track", ge=0, le=100, why="test values")
        false_probability: float = param(0.3, "probability a false slot holds a track in a block", ge=0.0,
                                         le=1.0, why="a probability")
        false_life_scans: int = param(4, "scans per block of a false slot", ge=1, le=100, why="test values")

    def run(self, batch, params) -> MultiTargetOutput:
        truth, sc = batch.truth, batch.scene
        n, K, T, _ = truth.shape
        F, L = params.false_slots, params.false_life_scans
        gens = [np.random.default_rng([7, int(t)]) for t in batch.trials]
        noise = np.stack([g.standard_normal((K, T, 2)) for g in gens]) * params.position_noise_m
        blocks = -(-K // L)
        spawn = np.stack([g.random((blocks, F)) for g in gens]) < params.false_probability
        where = np.stack([g.random((blocks, F, 2)) for g in gens])
        present = np.isfinite(truth[..., 0])
        start = _run_starts(present)
        age = np.where(present, np.arange(K)[None, :, None] - start, -1)
        state = np.where(present[..., None], truth, np.nan)
        state[..., 0] += noise[..., 0]
        state[..., 2] += noise[..., 1]
        status = np.where(present, np.where(age < params.delay_scans, 1, 2), 0)
        ids = np.where(present, np.arange(T)[None, None, :] * K + start, -1)
        # terminated: the scan after a confirmed run ends, at the last estimate
        ended = np.zeros_like(present)
        ended[:, 1:] = ~present[:, 1:] & present[:, :-1] & (age[:, :-1] >= params.delay_scans)
        status = np.where(ended, 3, status)
        state[:, 1:][ended[:, 1:]] = state[:, :-1][ended[:, 1:]]
        ids[:, 1:] = np.where(ended[:, 1:], ids[:, :-1], ids[:, 1:])
        # false tracks: confirmed, at a fixed random position of the region's bounding box, per block
        block = np.arange(K) // L
        on = spawn[:, block]                                                  # (n, K, F)
        r = sc.surveillance_region
        rng_ = r[0, 0] + (r[0, 1] - r[0, 0]) * where[:, block][..., 0]
        az = r[1, 0] + (r[1, 1] - r[1, 0]) * where[:, block][..., 1]
        false_state = np.stack([rng_ * np.sin(az), np.zeros_like(az), rng_ * np.cos(az), np.zeros_like(az)], -1)
        false_state[~on] = np.nan
        false_ids = np.where(on, T * K + np.arange(F)[None, None, :] * blocks + block[None, :, None], -1)
        cov = np.zeros((n, K, T + F, 2, 2))
        cov[..., 0, 0] = cov[..., 1, 1] = max(params.position_noise_m, 1.0) ** 2
        return MultiTargetOutput(state=np.concatenate([state, false_state], axis=2),
                                 track_id=np.concatenate([ids, false_ids], axis=2).astype(np.int64),
                                 status=np.concatenate([status, np.where(on, 2, 0)], axis=2).astype(np.int8),
                                 position_covariance=cov)
