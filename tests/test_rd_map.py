"""Scenario rd-map: shapes, exponential noise per region, targets where the truth
says, the null, common random numbers, validation."""

import numpy as np
import pytest

from radarbench.bench.errors import ConfigError
from radarbench.bench.params import build_params
from radarbench.bench.registry import get_scenario
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.bench.tasks.cells import CELL_DETECTION, REGION_NAMES, MapScene
from radarbench.models.rd_map import REGION_LEVEL_DB, background_power
from radarbench.scenarios.rd_map import RdMap

SMALL = RdMap.small_params


def make(snr_db, n=4, seed=1, **values):
    params = build_params(RdMap.Params, {**SMALL, **values})
    rng = TrialRNG(seed=seed, domain=0, scenario_key=0, trials=range(n))
    return RdMap().generate(params, snr_db, n, rng)


def test_registered():
    assert get_scenario("rd-map") is RdMap and RdMap.tasks == (CELL_DETECTION,)


def test_shapes_and_scene():
    b = make(10.0, n=3)
    R, D = SMALL["range_cells"], SMALL["doppler_cells"]
    assert b.z.shape == (3, 1, R, D) and b.z.dtype == np.float32 and b.t.shape == (1,)
    sc = b.scene
    assert type(sc) is MapScene and sc.shape == (R, D) and sc.region_names == REGION_NAMES
    assert sc.region_labels.dtype == np.int8 and sc.noise_power.shape == (3, R, D)
    present = set(np.unique(sc.region_labels))
    assert present == {0, 1, 2, 3}                    # every background is on by default
    T = sc.target_cells.shape[1]
    # one isolated target a region and one pair
    assert T == 4 * SMALL["targets_per_region"] + 2 * SMALL["pairs"]
    assert sc.target_paired.sum(axis=1).tolist() == [2, 2, 2]
    np.testing.assert_allclose(sc.target_snr_db, 10.0)
    labels = sc.region_labels[sc.target_cells[0, :, 0], sc.target_cells[0, :, 1]]
    assert set(labels[~sc.target_paired[0]]) == {0, 1, 2, 3}
    assert np.all(labels[sc.target_paired[0]] == 0)
    first, second = sc.target_cells[0][sc.target_paired[0]][:2]
    np.testing.assert_array_equal(second - first, SMALL.get("pair_offset_cells", (0, 4)))
    assert sc.swerling == 1 and sc.guard_cells == (1, 1)


def test_noise_is_exponential_with_the_scene_power_in_every_region():
    """Under the null, z / N is Exp(1) in every region: mean 1 and second moment 2,
    each within 5 standard errors (sd of Exp(1) is 1, of its square sqrt(20))."""
    b = make(None, n=200, seed=7)
    u = (b.z[:, 0] / b.scene.noise_power).astype(np.float64)
    for k in np.unique(b.scene.region_labels):            # the regions present
        name = REGION_NAMES[k]
        x = u[:, b.scene.region_labels == k].ravel()
        assert abs(x.mean() - 1.0) < 5 / np.sqrt(x.size), name
        assert abs((x ** 2).mean() - 2.0) < 5 * np.sqrt(20.0) / np.sqrt(x.size), name


def test_background_power_follows_the_parameters():
    p = build_params(RdMap.Params, SMALL)
    parts = background_power((p.range_cells, p.doppler_cells), bragg=(p.bragg_offset_bins, p.bragg_spread_bins,
                             p.bragg_cnr_db, p.bragg_cnr_far_db, p.bragg_asymmetry_db), interference=None, edge=None)
    D = p.doppler_cells
    assert parts.bragg[0, D // 2 + p.bragg_offset_bins] == pytest.approx(10 ** (p.bragg_cnr_db / 10))
    assert parts.bragg[-1, D // 2 + p.bragg_offset_bins] == pytest.approx(10 ** (p.bragg_cnr_far_db / 10))
    assert parts.bragg[0, D // 2 - p.bragg_offset_bins] == pytest.approx(
        10 ** ((p.bragg_cnr_db - p.bragg_asymmetry_db) / 10))
    b = make(None, n=1)
    N = b.scene.noise_power[0]
    assert N[p.edge_range_cell + 2, 1] == pytest.approx(10 ** (p.edge_step_db / 10))   # beyond the edge
    assert N[p.edge_range_cell - 2, 1] == pytest.approx(1.0)
    band = slice(p.interference_range_start, p.interference_range_start + p.interference_range_cells)
    assert N[band, D // 2].min() == pytest.approx(1 + 10 ** (p.interference_inr_db / 10))
    # regions: a component labels a cell where it is at least REGION_LEVEL_DB over the noise
    assert np.all(parts.bragg[b.scene.region_labels == 1] >= 10 ** (REGION_LEVEL_DB / 10) - 1e-12)


def test_targets_are_where_the_truth_says_and_nothing_else_changes():
    """Common random numbers: the map at an SNR equals the null map except at the
    target cells; a 40 dB non-fluctuating target is far above its cell's power."""
    null, sig = make(None, n=5, seed=3, swerling=0), make(40.0, n=5, seed=3, swerling=0)
    cells = sig.scene.target_cells
    changed = np.argwhere(sig.z[:, 0] != null.z[:, 0])
    expected = {(i, r, d) for i in range(5) for r, d in cells[i]}
    assert {tuple(x) for x in changed} <= expected
    ratio = sig.z[np.arange(5)[:, None], 0, cells[..., 0], cells[..., 1]] / \
        sig.scene.noise_power[np.arange(5)[:, None], cells[..., 0], cells[..., 1]]
    # |sqrt(S) + w|^2 / N >= (sqrt(1e4) - |w|/sqrt(N))^2 and |w|^2/N is Exp(1) (< 30 here)
    assert ratio.min() > (100 - np.sqrt(30)) ** 2
    np.testing.assert_allclose(sig.scene.realised_snr_db, 40.0)
    assert null.scene.target_cells.shape == (5, 0, 2) and np.all(np.isnan(null.scene.realised_snr_db))


def test_edge_sides_split_the_edge_band_at_the_step_with_targets_on_each_side():
    """With ``edge_sides`` the band's rows below the step are the quiet side, from it the
    raised side (outside the Bragg lines and the band); each side gets its own isolated
    targets, and nothing else in the layout's labels changes."""
    step, band = SMALL["edge_range_cell"], SMALL["edge_band_cells"]
    whole = make(None, n=1).scene.region_labels
    sides = make(10.0, n=1, edge_sides=True).scene
    quiet, raised = REGION_NAMES.index("clutter-edge-quiet"), REGION_NAMES.index("clutter-edge-raised")
    edge = whole == REGION_NAMES.index("clutter-edge")
    rows = np.arange(whole.shape[0])[:, None]
    np.testing.assert_array_equal(sides.region_labels == quiet, edge & (rows < step))
    np.testing.assert_array_equal(sides.region_labels == raised, edge & (rows >= step) & (rows < step + band))
    np.testing.assert_array_equal(sides.region_labels[~edge], whole[~edge])
    labels = sides.region_labels[sides.target_cells[0, :, 0], sides.target_cells[0, :, 1]]
    isolated = labels[~sides.target_paired[0]]
    assert (isolated == quiet).sum() == (isolated == raised).sum() == SMALL["targets_per_region"]
    assert not np.any(labels == REGION_NAMES.index("clutter-edge"))


def test_bragg_scale_varies_the_lines_strength_with_the_layout_held_fixed():
    """``bragg_scale_db`` multiplies the Bragg lines' power and nothing else: the region
    labels and the target cells are those of scale 0, even where the scaled lines fall
    below the labelling level (the layout is not re-derived from the weaker lines)."""
    strong = make(10.0, n=1, interference=False, clutter_edge=False).scene
    weak = make(10.0, n=1, interference=False, clutter_edge=False, bragg_scale_db=-20.0).scene
    np.testing.assert_array_equal(weak.region_labels, strong.region_labels)
    np.testing.assert_array_equal(weak.target_cells, strong.target_cells)
    # noise power = 1 + Bragg power: the Bragg part scales by 10^(-20/10)
    np.testing.assert_allclose(weak.noise_power - 1.0, 0.01 * (strong.noise_power - 1.0), rtol=1e-12, atol=1e-15)
    bragg = strong.region_labels == REGION_NAMES.index("bragg")
    assert (weak.noise_power[0][bragg] - 1.0).min() < 10 ** (REGION_LEVEL_DB / 10)   # some now below the level


def line_distance(cells: np.ndarray, doppler_cells: int, line_offset: int) -> np.ndarray:
    """Doppler cells from each (range, Doppler) cell to the nearer Bragg line's centre."""
    centres = doppler_cells // 2 + np.array([line_offset, -line_offset])
    return np.min(np.abs(cells[:, 1][:, None] - centres[None, :]), axis=1)


@pytest.mark.parametrize("offsets", [(0,), (2,), (4,), (1, 3)])
def test_bragg_targets_sit_at_the_stated_doppler_offsets_from_a_line(offsets):
    """``bragg_target_offsets_bins``: every Bragg-region target is that many Doppler cells
    from the centre of a line (either line, either side), inside the Bragg region; the
    labels are those of the unrestricted layout, and so are the other regions' targets
    here (the same shuffles; none of their cells is blocked by a moved Bragg target)."""
    p = dict(interference=False, clutter_edge=False, targets_per_region=2, pairs=0)
    free = make(10.0, n=1, **p).scene
    placed = make(10.0, n=1, bragg_target_offsets_bins=list(offsets), **p).scene
    D, line = SMALL["doppler_cells"], SMALL["bragg_offset_bins"]
    cells = placed.target_cells[0]
    labels = placed.region_labels[cells[:, 0], cells[:, 1]]
    bragg = labels == REGION_NAMES.index("bragg")
    assert bragg.sum() == 2
    distance = line_distance(cells[bragg], D, line)
    assert set(distance) <= set(offsets), distance
    np.testing.assert_array_equal(placed.region_labels, free.region_labels)
    free_cells = free.target_cells[0]
    free_bragg = free.region_labels[free_cells[:, 0], free_cells[:, 1]] == REGION_NAMES.index("bragg")
    np.testing.assert_array_equal(cells[~bragg], free_cells[~free_bragg])


def test_the_default_layout_puts_bragg_targets_off_the_stated_offset():
    """The check above can fail: without the parameter this layout's Bragg targets are not
    all 4 cells from a line (the shuffle places them anywhere in the region)."""
    scene = make(10.0, n=1, interference=False, clutter_edge=False, targets_per_region=2, pairs=0).scene
    D, line = SMALL["doppler_cells"], SMALL["bragg_offset_bins"]
    cells = scene.target_cells[0]
    bragg = scene.region_labels[cells[:, 0], cells[:, 1]] == REGION_NAMES.index("bragg")
    distance = line_distance(cells[bragg], D, line)
    assert set(distance) != {4}


#: (key, digest of z and the target cells) of the cfar preset's scenario configs that keep
#: their parameters, generated by the code before bragg_target_offsets_bins existed: a
#: parameter added at its default changes neither a stream nor a byte of the batches
#: (docs/architecture.md, 'Random streams')
CFAR_STREAMS = {"rd-map-mixed": (4281404860934479551, "e07a6e6698a3fc2f"),
                "rd-map-homogeneous": (1647383483866668309, "8ba8d68cc2e80579"),
                "rd-map-edge": (5097231971541663629, "f85020845ab9bda8")}


def test_the_cfar_presets_unchanged_configs_draw_the_same_bytes():
    import hashlib
    import importlib.resources
    import tomllib

    from radarbench.bench.sweep.config import parse_sweep
    from radarbench.bench.sweep.rng import EVALUATION

    preset = importlib.resources.files("radarbench.bench") / "presets" / "cfar.toml"
    plan = parse_sweep(tomllib.loads(preset.read_text(encoding="utf-8")))
    got = {}
    for config in plan.scenarios:
        if config.label in CFAR_STREAMS:
            b = RdMap().generate(config.params, 20.0, 2, TrialRNG(620, EVALUATION, config.key, range(2)))
            digest = hashlib.sha256(np.ascontiguousarray(b.z).tobytes()
                                    + np.ascontiguousarray(b.scene.target_cells).tobytes()).hexdigest()[:16]
            got[config.label] = (config.key, digest)
    assert got == CFAR_STREAMS


def test_bragg_target_offsets_outside_the_region_name_the_field():
    with pytest.raises(ConfigError) as err:
        RdMap().check_config(build_params(RdMap.Params, {**SMALL, "bragg_target_offsets_bins": [40]}))
    assert "bragg_target_offsets_bins" in str(err.value)
    with pytest.raises(ConfigError) as err:
        build_params(RdMap.Params, {**SMALL, "bragg": False, "bragg_target_offsets_bins": [2]})
    assert "bragg_target_offsets_bins" in str(err.value)


def test_swerling1_target_cells_are_exponential_with_mean_signal_plus_noise():
    """Swerling 1 in complex Gaussian noise: z / N ~ Exp(1 + S); the mean over
    400 maps x T targets lies within 5 standard errors of 1 + S."""
    b = make(6.0, n=400, seed=11, swerling=1)
    cells = b.scene.target_cells
    rows = np.arange(400)[:, None]
    ratio = b.z[rows, 0, cells[..., 0], cells[..., 1]] / b.scene.noise_power[rows, cells[..., 0], cells[..., 1]]
    mean = 1 + 10 ** 0.6
    assert abs(ratio.mean() - mean) < 5 * mean / np.sqrt(ratio.size)


def test_same_trial_same_map_whatever_the_batch():
    a = make(8.0, n=4, seed=5)
    params = build_params(RdMap.Params, SMALL)
    b = RdMap().generate(params, 8.0, 2, TrialRNG(seed=5, domain=0, scenario_key=0, trials=[2, 3]))
    np.testing.assert_array_equal(a.z[2:], b.z)


@pytest.mark.parametrize("values, field", [
    ({"pair_offset_cells": [0, 0]}, "pair_offset_cells"),
    ({"targets_per_region": 40}, "targets_per_region"),
    ({"bragg_offset_bins": 60}, "bragg_offset_bins"),
    ({"edge_range_cell": 60}, "edge_range_cell"),
    ({"margin_cells": 24}, "margin_cells"),
])
def test_bad_configs_name_the_field(values, field):
    with pytest.raises(ConfigError) as err:
        RdMap().check_config(build_params(RdMap.Params, {**SMALL, **values}))   # the room: after the memory check
    assert field in str(err.value)


def test_backgrounds_can_be_switched_off():
    b = make(None, n=1, bragg=False, interference=False, clutter_edge=False)
    assert set(np.unique(b.scene.region_labels)) == {0}
    np.testing.assert_allclose(b.scene.noise_power, 1.0)
