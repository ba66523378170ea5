"""The DP-TBD kernels against their frozen predecessors (tests/tbd_kernels_oracle.py): bit for bit.

The kernels of :mod:`methods.tbd.kernels`, :mod:`methods.tbd.mf_kernels` and :mod:`methods.tbd.alongtrack`
compute the maxima only, factorise the maximum over d' by heading classes,
run as a row wavefront with checkpoints and recompute the backpointers on the
track. None of that may change a result: score, track and value map must be
the ones of the original max + argmax kernels, ties included (integer-valued
frames, flat turn prior), at the grid edges and on scenes smaller than the
window.
"""

import math
import zlib

import numpy as np
import pytest

import radarbench.methods.tbd.alongtrack as alongtrack
import radarbench.methods.tbd.kernels as kernels
import radarbench.methods.tbd.mf_kernels as mf_kernels
import tbd_kernels_oracle as oracle   # beside this file: the previous kernels, frozen
from radarbench.bench.core import Batch
from radarbench.bench.params import build_params
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.bench.tasks.tbd import Grid, TBDScene
from radarbench.methods.tbd import dp_tbd
from radarbench.methods.tbd.dp_tbd import LOG_UNIFORM_ANGLE, DpTbd, DpTbdMf
from radarbench.scenarios.tbd_grid import TbdGrid


def frames_batch(z, gamma=(1.0, 0.0, 0.0)):
    """A TBD batch of the frames ``z`` on 100 m cells at 1 s, noise autocovariance ``gamma``."""
    z = np.asarray(z, np.float32)
    n, K, H, W = z.shape
    scene = TBDScene(grid=Grid(rows=H, cols=W, cell_m=100.0, x_min_m=0.0, y_min_m=0.0), frame_period_s=1.0,
                     noise_std=math.sqrt(gamma[0]), noise_autocovariance=np.asarray(gamma, float))
    return Batch(t=np.arange(K, dtype=float), truth=np.zeros((n, K, 4)), z=z, scene=scene, trials=np.arange(n))


def run_both(monkeypatch, cls, batch, params):
    """(new, oracle) outputs of one method on one batch."""
    new = cls().run(batch, params)
    with monkeypatch.context() as m:
        m.setattr(dp_tbd, "kernels", oracle)
        m.setattr(dp_tbd, "mf_kernels", oracle)
        m.setattr(dp_tbd, "alongtrack", oracle)
        old = cls().run(batch, params)
    return new, old


def assert_identical(new, old):
    # tobytes: equal bits, not merely equal values (-0.0 vs 0.0 would fail)
    assert new.score.tobytes() == old.score.tobytes()
    np.testing.assert_array_equal(new.track, old.track)
    assert new.value.tobytes() == old.value.tobytes()


def random_frames(rng, n, K, H, W, ties):
    if ties:                                   # few distinct values: many exact ties
        return rng.integers(-2, 3, size=(n, K, H, W)).astype(np.float32)
    return rng.normal(size=(n, K, H, W)).astype(np.float32)


SHAPES = [(1, 1, 1, 1), (2, 2, 3, 2), (1, 3, 1, 9), (2, 4, 6, 5), (1, 7, 9, 11), (2, 9, 12, 10),
          (1, 14, 13, 17), (1, 20, 16, 16)]


@pytest.mark.parametrize("ties", [False, True])
@pytest.mark.parametrize("shape", SHAPES)
def test_dp_tbd_equals_the_original_kernel(monkeypatch, shape, ties):
    rng = np.random.default_rng(zlib.crc32(repr((shape, ties)).encode()))
    batch = frames_batch(random_frames(rng, *shape, ties))
    for q in (1, 2, 3):
        new, old = run_both(monkeypatch, DpTbd, batch, DpTbd.Params(max_speed_m_s=100.0 * q))
        assert_identical(new, old)


@pytest.mark.parametrize("likelihood", ["per-cell", "along-track"])
@pytest.mark.parametrize("ties", [False, True])
@pytest.mark.parametrize("shape", SHAPES)
def test_dp_tbd_mf_equals_the_original_kernel(monkeypatch, shape, ties, likelihood):
    rng = np.random.default_rng(zlib.crc32(repr((shape, ties, likelihood)).encode()))
    for gamma in [(1.0, 0.0, 0.0), (1.0, 0.903, 0.683)]:
        batch = frames_batch(random_frames(rng, *shape, ties), gamma)
        for q in (1, 2, 3):
            # kappa = 0: a flat turn prior, so ties between headings as well
            for kappa in (0.0, 5.0):
                params = build_params(DpTbdMf.Params, {"max_speed_m_s": 100.0 * q, "turn_concentration": kappa,
                                                       "likelihood": likelihood})
                new, old = run_both(monkeypatch, DpTbdMf, batch, params)
                assert_identical(new, old)


@pytest.mark.parametrize("q", [4, 5])
def test_wide_windows(monkeypatch, q):
    rng = np.random.default_rng(q)
    batch = frames_batch(random_frames(rng, 1, 8, 14, 13, False), (1.0, 0.903, 0.683))
    new, old = run_both(monkeypatch, DpTbd, batch, DpTbd.Params(max_speed_m_s=100.0 * q))
    assert_identical(new, old)
    for likelihood in ("per-cell", "along-track"):
        params = build_params(DpTbdMf.Params, {"max_speed_m_s": 100.0 * q, "likelihood": likelihood})
        assert_identical(*run_both(monkeypatch, DpTbdMf, batch, params))


def test_tracks_that_run_along_the_grid_edges(monkeypatch):
    """A strong target on the border rows and columns: the track's states
    sit next to the -inf states of off-grid predecessors."""
    rng = np.random.default_rng(5)
    K, H, W = 12, 10, 11
    z = rng.normal(size=(2, K, H, W)).astype(np.float32)
    path = [(0, 0), (0, 2), (0, 4), (1, 6), (0, 8), (0, 10), (2, 10), (4, 10), (6, 10), (8, 10), (9, 9), (9, 7)]
    for k, (r, c) in enumerate(path):
        z[0, k, r, c] += 6.0
        z[1, k, H - 1 - r, W - 1 - c] += 6.0
    batch = frames_batch(z, (1.0, 0.903, 0.683))
    new, old = run_both(monkeypatch, DpTbd, batch, DpTbd.Params())
    assert_identical(new, old)
    np.testing.assert_array_equal(new.track[0], path)                # the test is about the edges
    for likelihood in ("per-cell", "along-track"):
        params = build_params(DpTbdMf.Params, {"likelihood": likelihood})
        assert_identical(*run_both(monkeypatch, DpTbdMf, batch, params))


@pytest.mark.parametrize("config", [{}, {"prewhiten": True}, {"likelihood": "per-cell"},
                                    {"likelihood": "along-track"}, {"turn_prior": "laplace"}])
def test_tbd_grid_batches(monkeypatch, config):
    """Real scenes (default AR(3) noise, the paper's turning target) at 48 x 48
    cells, 20 frames, with and without a target."""
    cls = DpTbd if config in ({}, {"prewhiten": True}) else DpTbdMf
    params = build_params(cls.Params, config)
    scene_params = build_params(TbdGrid.Params, {"cells": 48})
    for snr_db in (None, 3.0):
        batch = TbdGrid().generate(scene_params, snr_db, 3, TrialRNG(11, 0, 7, range(3)))
        assert_identical(*run_both(monkeypatch, cls, batch, params))


def mf_arguments(rng, q, structured):
    """Kernel arguments of dp-tbd-mf with random coefficients; ``structured``:
    the turn weights of a heading prior, else a table without heading
    structure (every displacement its own class)."""
    D = (2 * q + 1) ** 2
    if structured:
        lp = dp_tbd.transition_log_weights(q, "von-mises", 3.0).astype(np.float32)
    else:
        lp = np.round(rng.normal(size=(D, D)), 1).astype(np.float32)     # rounded: ties too
    f = lambda *shape: rng.normal(size=shape).astype(np.float32)        # noqa: E731
    return (lp, np.float32(LOG_UNIFORM_ANGLE), np.float32(0.4), f(2), f(1), f(1), f(2), f(2), f(4), f(4))


@pytest.mark.parametrize("structured", [True, False])
@pytest.mark.parametrize("q", [1, 2])
def test_kernels_with_any_turn_weights(q, structured):
    """The heading-class factorisation only applies when lp has heading
    structure; otherwise each displacement is its own class, and the result
    is still the original kernel's."""
    rng = np.random.default_rng(q + 10 * structured)
    classes = mf_kernels._heading_classes(mf_arguments(rng, q, structured)[0], q)[4].shape[0]
    assert (classes < (2 * q + 1) ** 2) == (structured and q > 1)     # q = 1: nine headings
    for shape in [(2, 9, 11, 12), (1, 3, 4, 5)]:
        z = random_frames(rng, *shape, ties=not structured)
        n, K, H, W = shape
        args = mf_arguments(rng, q, structured)
        outs = []
        for module in (mf_kernels, oracle):
            score, track, value = np.empty(n), np.empty((n, K, 2), np.int64), np.empty((n, H, W), np.float32)
            module.dp_tbd_mf(z, q, *args, score, track, value)
            outs.append((score, track, value))
        for new, old in zip(*outs):
            assert new.tobytes() == old.tobytes()
        lp = args[0]
        c = [np.float32(x) for x in rng.normal(size=10)]
        outs = []
        for fn in (alongtrack.dp_tbd_mf_along_track, oracle.dp_tbd_mf_along_track):
            score, track, value = np.empty(n), np.empty((n, K, 2), np.int64), np.empty((n, H, W), np.float32)
            fn(z, q, lp, *c, score, track, value)
            outs.append((score, track, value))
        for new, old in zip(*outs):
            assert new.tobytes() == old.tobytes()


def test_heading_classes_of_the_default_window():
    """q = 2: 16 headings (8 with two members, 8 knight moves) and d = 0."""
    lp = dp_tbd.transition_log_weights(2, "von-mises", 5.0).astype(np.float32)
    cls, members, nmem, neg, L, cand = mf_kernels._heading_classes(lp, 2)
    assert L.shape == (17, 17) and cand.shape == (17, 16)
    assert sorted(nmem) == [1] * 9 + [2] * 8
    disp = dp_tbd.displacements(2)
    for u in range(17):
        m = members[u, :nmem[u]]
        cross = disp[m[0], 0] * disp[m, 1] - disp[m[0], 1] * disp[m, 0]
        assert (cross == 0).all()                                   # one heading
        assert (disp[m] @ disp[m[0]] >= 0).all()
        assert cls[len(disp) - 1 - m[0]] == neg[u]                   # -d is in class neg[u]


def test_signed_zeros():
    """Merits that are all +0 or -0 (zero weights and coefficients): the
    sign of a zero maximum must not depend on how the candidates are
    grouped either."""
    rng = np.random.default_rng(0)
    for it in range(60):
        K, H, W = (int(x) for x in rng.integers(1, 8, size=3))
        z = np.where(rng.random((1, K, H, W)) < 0.5, np.float32(0.0), np.float32(-0.0)).astype(np.float32)
        if it % 2:
            z[rng.random(z.shape) < 0.2] = 1.0
        for q in (1, 2):
            D = (2 * q + 1) ** 2
            lp = np.zeros((D, D), np.float32)
            zero, one = np.zeros(4, np.float32), np.ones(4, np.float32)
            # coef = 1, const = 0 for every Lambda plane: the merits are sums of +-0
            mf = (lp, np.float32(0), np.float32(0), zero[:2], one[:1], zero[:1], one[:2], zero[:2], one, zero)
            at = (lp,) + tuple(np.float32(x) for x in (0, 0, 0, 0, 1, 0, 1, 0, 1, 0))
            calls = [(kernels.dp_tbd, oracle.dp_tbd, ()), (mf_kernels.dp_tbd_mf, oracle.dp_tbd_mf, mf),
                     (alongtrack.dp_tbd_mf_along_track, oracle.dp_tbd_mf_along_track, at)]
            for new_fn, old_fn, args in calls:
                outs = []
                for fn in (new_fn, old_fn):
                    out = (np.empty(1), np.empty((1, K, 2), np.int64), np.empty((1, H, W), np.float32))
                    fn(z, q, *args, *out)
                    outs.append(out)
                for new, old in zip(*outs):
                    assert new.tobytes() == old.tobytes()
