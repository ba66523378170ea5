"""Per-cell Pfa of TBD value maps from kept order statistics, and the sweep's chance Pd."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from radarbench.bench.calibration import EXACT_CELL_RANKS, cell_calibration, cell_exceedances, cell_order_statistics, cell_ranks
from radarbench.bench.sweep.config import parse_sweep_text
from radarbench.bench.errors import ConfigError


@given(cells=st.integers(1, 5000))
def test_ranks_start_exact_and_end_at_the_cell_count(cells):
    r = cell_ranks(cells)
    assert r[0] == 1 and r[-1] == cells and np.all(np.diff(r) > 0)
    assert np.array_equal(r[:min(cells, EXACT_CELL_RANKS)], np.arange(1, min(cells, EXACT_CELL_RANKS) + 1))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31), cells=st.integers(1, 3000), q=st.floats(0.0, 1.0))
def test_exceedance_bracket_contains_the_true_count(seed, cells, q):
    """The kept order statistics bracket the number of cells at or above any threshold,
    exactly when it is below EXACT_CELL_RANKS."""
    rng = np.random.default_rng(seed)
    maps = rng.standard_normal((3, cells)).round(1)      # ties included
    t = float(np.quantile(maps, q))
    low, high = cell_exceedances(cell_order_statistics(maps), t)
    true = (maps >= t).sum(axis=1)
    assert np.all(low <= true) and np.all(true <= high)
    exact = true < EXACT_CELL_RANKS
    assert np.array_equal(low[exact], true[exact]) and np.array_equal(high[exact], true[exact])


def test_cell_threshold_hits_the_requested_per_cell_pfa():
    """On independent N(0, 1) cells the per-cell threshold at Pfa p is the normal
    (1 - p) quantile within sampling error, and a scene threshold's per-cell Pfa is
    bracketed by its interval."""
    rng = np.random.default_rng(7)
    maps = rng.standard_normal((400, 2500))
    stats = cell_order_statistics(maps)
    scores = maps.max(axis=1)
    pfa = 1e-3
    point, low, high, t_cell, scene = cell_calibration(stats, scores, 3.5, pfa)
    true = float((maps >= 3.5).mean())
    assert low <= true <= high and abs(point - true) <= 0.5 * true + 1e-6
    assert float((maps >= t_cell).mean()) == pytest.approx(pfa, rel=0.1)   # 1000 cells: sd 3 %
    assert scene == pytest.approx(float((scores >= t_cell).mean()))


def _sweep(calibration: str) -> str:
    return ('name = "x"\nscenario = "cv-turn-cv"\ntrials = 10\nseed = 1\nsnr_db = [0]\n'
            '[[methods]]\nname = "innovation"\n' + calibration).encode()


def test_chance_pd_is_a_sweep_setting_and_keeps_old_fingerprints():
    default = parse_sweep_text(_sweep(""), "s.toml")
    same = parse_sweep_text(_sweep("[calibration]\nchance_pd = 0.05\n"), "s.toml")
    other = parse_sweep_text(_sweep("[calibration]\nchance_pd = 0.1\n"), "s.toml")
    assert default.calibration.chance_pd == 0.05 and other.calibration.chance_pd == 0.1
    assert default.fingerprint() == same.fingerprint() != other.fingerprint()
    assert "chance_pd" not in default.to_dict()["calibration"]
    with pytest.raises(ConfigError, match="calibration.chance_pd"):
        parse_sweep_text(_sweep("[calibration]\nchance_pd = 0.7\n"), "s.toml")
