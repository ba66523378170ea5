"""Method ``cfar-track``: the HFSWR chapter's detect-and-track chain, composed from a
registered cell detector and a registered multi-target tracker."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from radarbench.bench.core import Batch, Method
from radarbench.bench.params import param
from radarbench.bench.registry import register_method
from radarbench.bench.tasks.cells import CELL_DETECTION, MapScene
from radarbench.bench.tasks.detecttrack import DETECT_TRACK, DetectTrackOutput, DetectTrackScene
from radarbench.bench.tasks.multitarget import CLUTTER, MULTI_TARGET, PADDING, MultiTargetScene
from radarbench.methods.chain.compose import component
from radarbench.methods.chain.plots import extract_plots

#: a uniform error over one cell has std cell / sqrt(12): the plots' range and radial-velocity
#: noise the trackers assume
SQRT_12 = math.sqrt(12.0)


def detector_of(params) -> tuple:
    """(detector instance, its params) of ``params.detector``, a ``cell-detection`` method."""
    return component(params.detector, "detector", CELL_DETECTION)


def tracker_of(params) -> tuple:
    """(tracker instance, its params) of ``params.tracker``, a ``multi-target`` method."""
    return component(params.tracker, "tracker", MULTI_TARGET)


@register_method
class CfarTrack(Method):
    r"""CFAR with peak detection on each scan's range-Doppler map, plots, then a multi-target tracker: the HFSWR chapter's chain.

    After "目标检测与跟踪方法 (Target detection and tracking methods),
    海洋遥感技术应用": CFAR along range and Doppler, combined, with peak
    detection (section 1, Fig. 6.20), then M/N initiation, JPDA and a UKF in
    range, azimuth and radial velocity (section 2, Fig. 6.25), tracking
    "reducing false alarms and forming tracks". Both halves are registered
    methods named by parameters, ``detector = "os-cfar[k_range=12]"``,
    ``tracker = "jpda-ukf"`` (``name[key=value,...]``, a config label's
    form; :mod:`methods.chain.compose`), checked when the sweep is read like
    any parameter, so one sweep crosses detectors and trackers.

    Per batch: the n K maps go to the detector as one ``cell-detection`` batch
    (its :class:`~bench.tasks.cells.MapScene`: the scene's region labels and
    mean power, which ``region-adaptive`` reads as its oracle segmentation, and
    the targets' cells, with SNR NaN where a target is absent, which no CFAR
    reads); a cell is declared where its statistic reaches the detector's
    nominal threshold at ``pfa``. The declared cells become plots
    (:mod:`methods.chain.plots`: one per cell, centroid in range and Doppler,
    the scene's direction of arrival as azimuth). The tracker then gets a
    :class:`~bench.tasks.multitarget.MultiTargetScene` of those plots.

    **What the tracker is told** (the chapter prints none of it; ours): the
    measurement stds of a uniform error over one cell, $\sigma_r = \Delta r / \sqrt{12}$,
    $\sigma_{v_r} = \Delta v / \sqrt{12}$, and the scene's DOA std for azimuth; the clutter
    density of the detector's nominal false alarms, $\lambda = P_{fa} R D / V$
    ($R D$ the cells of a map, $V$ the volume of range x azimuth x radial velocity
    the maps cover), the
    Pd ``tracker_pd`` (a detector's Pd is not known to the system that uses
    it); the scan period, the sensor, the speed bounds and process noise of the
    scene. Plots carry no origin (every one is marked clutter): the tracker
    does not read it.
    """

    name = "cfar-track"
    task = DETECT_TRACK

    @dataclass(frozen=True)
    class Params:
        detector: str = param("ca-cfar", "the cell detector: a registered cell-detection method, name or "
                                         "name[key=value,...] (e.g. os-cfar[k_range=12])")
        tracker: str = param("jpda-ukf", "the multi-target tracker: a registered multi-target method, name or "
                                         "name[key=value,...] (e.g. gnn-ekf[confirm_m=3])")
        pfa: float = param(1e-3, "nominal per-cell false-alarm probability of the detector's threshold",
                           ge=1e-12, le=0.1, why="a threshold at all (0.1) down to none in any map")
        tracker_pd: float = param(0.7, "the detection probability the tracker assumes (JPDA's Pd)", ge=0.05,
                                  le=0.999, why="a tracker assuming Pd below 0.05 or at 1 has no use for plots "
                                                "or for misses")

        def validate(self) -> None:
            detector_of(self)
            tracker_of(self)

    def check_scenario(self, params, scenario_params) -> str | None:
        (detector, detector_params), (tracker, tracker_params) = detector_of(params), tracker_of(params)
        return (detector.check_scenario(detector_params, scenario_params)
                or tracker.check_scenario(tracker_params, scenario_params))

    def identity_modules(self, params) -> tuple[str, ...]:
        """The detector's and the tracker's modules (and what they name in turn): their code
        computes this config's numbers, reached through the registry."""
        return tuple(module for part, part_params in (detector_of(params), tracker_of(params))
                     for module in (type(part).__module__, *part.identity_modules(part_params)))

    def unit_memory_bytes(self, params, scenario_params, n: int) -> int | None:
        """The detector's on the unit's n K maps."""
        detector, detector_params = detector_of(params)
        return detector.unit_memory_bytes(detector_params, scenario_params, n * getattr(scenario_params, "scans", 1))

    def least_cost(self, batch: Batch, params, output) -> str:
        return "the sum of its detector's and tracker's, the tracker's following the plots: no floor holds"

    def run(self, batch: Batch, params) -> DetectTrackOutput:
        scene = batch.scene
        if not isinstance(scene, DetectTrackScene):
            raise TypeError(f"expected a DetectTrackScene, got {type(scene).__name__}")
        detected = self.detect(batch, params)
        cells, plots, counts = extract_plots(batch.z, detected, scene.azimuth_rad, scene.range_start_m,
                                             scene.range_cell_m, scene.velocity_start_m_s, scene.velocity_cell_m_s)
        tracker, tracker_params = tracker_of(params)
        tracks = tracker.run(plot_batch(batch, plots, counts, params), tracker_params)
        return DetectTrackOutput(state=tracks.state, track_id=tracks.track_id, status=tracks.status,
                                 position_covariance=tracks.position_covariance, plot_cells=cells, plots=plots)

    @staticmethod
    def detect(batch: Batch, params) -> np.ndarray:
        """(n, K, R, D) bool: the cells the detector declares at its nominal threshold for ``pfa``."""
        detector, detector_params = detector_of(params)
        n, K, R, D = batch.z.shape
        maps = map_batch(batch)
        statistic = detector.run(maps, detector_params).statistic
        threshold = detector.nominal_threshold(detector_params, params.pfa, maps)
        return (np.asarray(statistic) >= threshold).reshape(n, K, R, D)


def map_batch(batch: Batch) -> Batch:
    """The batch's n K maps as one ``cell-detection`` batch (the class docstring)."""
    scene = batch.scene
    n, K, R, D = batch.z.shape
    cells = scene.target_cells.reshape(n * K, -1, 2)
    present = cells[..., 0] >= 0
    maps_scene = MapScene(
        snr_definition=scene.snr_definition, realised_snr_db=np.repeat(scene.realised_snr_db, K),
        region_labels=scene.region_labels, region_names=scene.region_names,
        noise_power=np.broadcast_to(scene.noise_power, (n * K, R, D)),
        target_cells=np.where(present[..., None], cells, 0), target_snr_db=np.where(
            present, np.repeat(scene.realised_snr_db, K)[:, None], np.nan),
        target_paired=np.zeros(present.shape, bool), swerling=1, guard_cells=scene.guard_cells)
    return Batch(t=np.zeros(1), truth=np.zeros((n * K, 1, 2)), z=batch.z.reshape(n * K, 1, R, D),
                 scene=maps_scene, trials=np.arange(n * K))


def plot_batch(batch: Batch, plots: np.ndarray, counts: np.ndarray, params) -> Batch:
    """The tracker's batch: the plots with the scene the class docstring states."""
    scene = batch.scene
    region = scene.surveillance_region
    R, D = scene.shape
    std = np.array([scene.range_cell_m / SQRT_12, scene.azimuth_std_rad, scene.velocity_cell_m_s / SQRT_12])
    slots = np.arange(plots.shape[2])
    tracker_scene = MultiTargetScene(
        snr_definition=scene.snr_definition, realised_snr_db=scene.realised_snr_db,
        position_index=scene.position_index, n_plots=counts.astype(np.int64),
        plot_origin=np.where(slots < counts[..., None], CLUTTER, PADDING).astype(np.int64),
        scan_period_s=scene.scan_period_s, sensor_xy=scene.sensor_xy, measurement_std=std,
        clutter_density=float(params.pfa * R * D / np.prod(np.diff(region, axis=1))),
        surveillance_region=region, pd=float(params.tracker_pd), speed_bounds_m_s=scene.speed_bounds_m_s,
        accel_std_m_s2=scene.accel_std_m_s2, gospa_cutoff_m=scene.gospa_cutoff_m, gospa_order=scene.gospa_order)
    return Batch(t=batch.t, truth=batch.truth, z=plots, scene=tracker_scene, trials=batch.trials)
