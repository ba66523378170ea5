"""Track-before-detect: a scene score thresholded at a per-scene Pfa, and a
backtracked track scored against the true cells.

A TBD method returns a :class:`~bench.core.TBDOutput`; the harness calibrates
the scene threshold on null scenes (empirical quantile, a Gumbel fit as in
Johnston & Krishnamurthy, IEEE TAES 38(1), 2002, or a generalized Pareto tail), reads the same threshold
per cell on the null value maps, and scores detection and position error
(:mod:`bench.tasks.tbd.metrics`; docs/architecture.md, 'Tasks'), as the
multi-frame DP-TBD paper and Tonissen & Evans (IEEE TAES 32(4), 1996) do.

Its scenarios put a :class:`TBDScene` on the batch: the :class:`Grid`, the
frame period, the true cells and the noise model
(docs/architecture.md, 'Scenes').

A recorded trial keeps, of the scene, the frames (quantised), the grid and
the true cells; per method, the backtracked cells, the last-frame value map
(quantised) and the scene score. Entities::

    .../frames                  DepthImage per step (uint8 codes, viridis), grid as static AnyValues
    .../frames/truth_track      true cells: Points2D per step + static LineStrips2D, pixel coords
    .../frames/{method}_track   backtracked cells of a method, same form
    .../{method}/score          Scalars: the scene score, a flat line over the steps
    .../{method}/threshold      Scalars: the scene threshold (when the score is drawn)
    .../{method}/value          static DepthImage: merit map at the last frame (uint8 codes, inferno)

Images are north up like positions: grid row ``r`` (``y = y_min + (r + 0.5)·cell_m``)
is drawn at image row ``rows - 1 - r``, so a cell ``(row, col)`` is at pixel
``(col + 0.5, rows - row - 0.5)``, where the track strips are logged. Cells
outside the grid (e.g. -1) are left out of the strips; a score or threshold
that is non-finite is not drawn.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from radarbench.bench.calibration import cell_order_statistics
from radarbench.bench.core import TBD, Batch, Scene, TBDOutput, has_shape, require
from radarbench.bench.metrics import per_step_rmse
from radarbench.bench.recording.axes import frame_of, log_axes
from radarbench.bench.recording.blueprint import Views, relative, trial_time_axis
from radarbench.bench.recording.draw import COLOUR_SCALE, log_image, log_image_series, log_series, log_track
from radarbench.bench.recording.layout import TRUTH_COLOR, MethodLayout, TrialLayout
from radarbench.bench.recording.paths import rerun_path
from radarbench.bench.recording.record import MethodTrace, TrialRecord, check_shape
from radarbench.bench.tasks.base import OutputError, RecordedScene, ReportContext, Task, check_finite, time_series
from radarbench.bench.tasks.tbd.metrics import summarise_tbd, tbd_trial_metrics, unit_innovation_snr_offset_db

#: this module computes stored numbers: its code belongs to the identity of every config
#: that loads it (docs/architecture.md, 'Identities')
COMPUTES_RESULTS = True

__all__ = ["GRID_KEYS", "Grid", "TBDScene", "TBDTask", "method_trace", "scene"]

#: Keys of a grid: cell ``(row, col)`` has its centre at
#: ``x = x_min_m + (col + 0.5)·cell_m``, ``y = y_min_m + (row + 0.5)·cell_m``.
GRID_KEYS = ("rows", "cols", "cell_m", "x_min_m", "y_min_m")
_FRAMES_COLORMAP = "viridis"
_VALUE_COLORMAP = "inferno"


# ------------------------------------------------------------------ what the scenario tells the methods

def _count(x) -> bool:
    return isinstance(x, (int, np.integer)) and not isinstance(x, bool)


def _number(x) -> bool:
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, bool) and math.isfinite(x)


@dataclass(frozen=True, eq=False)
class Grid:
    """The cell grid of a TBD scene. Cell ``(row, col)`` covers x in
    [x_min_m + col cell_m, x_min_m + (col + 1) cell_m) and likewise y for rows;
    its centre is ``x_min_m + (col + 0.5) cell_m`` (row ↔ y, col ↔ x)."""

    #: number of rows H (cells along y)
    rows: int
    #: number of columns W (cells along x)
    cols: int
    #: cell size (m)
    cell_m: float
    #: x of the grid's west edge (m)
    x_min_m: float
    #: y of the grid's south edge (m)
    y_min_m: float

    def __post_init__(self) -> None:
        for name in ("rows", "cols"):
            require(self, name, _count(getattr(self, name)) and getattr(self, name) > 0, "an int > 0")
        require(self, "cell_m", _number(self.cell_m) and self.cell_m > 0, "a number > 0 (m)")
        for name in ("x_min_m", "y_min_m"):
            require(self, name, _number(getattr(self, name)), "a finite number (m)")

    def as_dict(self) -> dict:
        """The grid as a dict of :data:`GRID_KEYS` (metrics, recordings)."""
        return {k: getattr(self, k) for k in GRID_KEYS}


@dataclass(frozen=True, kw_only=True, eq=False)
class TBDScene(Scene):
    """What a track-before-detect scenario tells the methods and the harness
    (docs/architecture.md, 'Scenes'), besides :class:`~bench.core.Scene`'s
    fields. The frames ``z`` are (n, K, rows, cols); the noise of each cell is
    a zero-mean stationary process over frames (the multi-frame DP-TBD paper's
    AR model, or white), independent across cells.
    """

    #: the cell grid of the frames
    grid: Grid
    #: frame period T (s)
    frame_period_s: float
    #: (n, K, 2) integer (row, col) of the target per frame; None under the null (no target)
    target_cells: np.ndarray | None = None
    #: sigma, the stationary noise std per cell
    noise_std: float = 1.0
    #: (L,) gamma(0..L-1), the noise autocovariance over frames at lags 0..L-1 (lags
    #: beyond are 0); None: white noise of variance noise_std^2
    noise_autocovariance: np.ndarray | None = None
    #: (a1, ..., aP) of the noise's AR model v_k + a1 v_(k-1) + ... + aP v_(k-P) = w_k; None: white
    ar_coefficients: tuple[float, ...] | None = None
    #: a backtracked cell is a hit within this Chebyshev distance of the true cell (cells)
    hit_tolerance_cells: int = 1
    #: (n, K) target amplitude per frame (zeros under the null); None: not given
    amplitude: np.ndarray | None = None

    @property
    def target_present(self) -> bool:
        """Whether the scene has a target (false under the null)."""
        return self.target_cells is not None

    def __post_init__(self) -> None:
        super().__post_init__()
        require(self, "grid", isinstance(self.grid, Grid), "a bench.tasks.tbd.Grid")
        require(self, "frame_period_s", _number(self.frame_period_s) and self.frame_period_s > 0, "a number > 0 (s)")
        require(self, "target_cells", self.target_cells is None or has_shape(self.target_cells, (None, None, 2), "iu"),
                "None or an (n, K, 2) integer array")
        require(self, "noise_std", _number(self.noise_std) and self.noise_std > 0, "a number > 0")
        require(self, "noise_autocovariance", self.noise_autocovariance is None
                or has_shape(self.noise_autocovariance, (None,), "f"), "None or an (L,) float array")
        require(self, "ar_coefficients", self.ar_coefficients is None or (isinstance(self.ar_coefficients, tuple)
                and all(_number(a) for a in self.ar_coefficients)), "None or a tuple of numbers")
        require(self, "hit_tolerance_cells", _count(self.hit_tolerance_cells) and self.hit_tolerance_cells >= 0,
                "an int >= 0")
        require(self, "amplitude", self.amplitude is None or has_shape(self.amplitude, (None, None), "f"),
                "None or an (n, K) float array")

    def check(self, batch: Batch) -> None:
        super().check(batch)
        n, K, g = batch.n, batch.steps, self.grid
        require(self, "grid", batch.z.shape[2:] == (g.rows, g.cols),
                f"rows x cols = frames' {batch.z.shape[2:]}, not {g.rows} x {g.cols}")
        for name, shape in (("target_cells", (n, K, 2)), ("amplitude", (n, K))):
            value = getattr(self, name)
            require(self, name, value is None or value.shape == shape, f"shape {shape}")


# ------------------------------------------------------------------ what a recorded trial keeps

def _grid(grid) -> dict:
    """The grid dict with exactly GRID_KEYS, ints and floats; ValueError if not."""
    missing = [k for k in GRID_KEYS if k not in grid]
    if missing:
        raise ValueError(f"TrialRecord.grid: missing key(s) {', '.join(missing)}")
    out = {"rows": int(grid["rows"]), "cols": int(grid["cols"])}
    out.update({k: float(grid[k]) for k in GRID_KEYS[2:]})
    if out["rows"] <= 0 or out["cols"] <= 0 or not out["cell_m"] > 0:
        raise ValueError(f"TrialRecord.grid: rows, cols and cell_m must be > 0, got {out}")
    return out


def _cells(cells, where: str) -> np.ndarray:
    """Integer (K, 2) cells as int32."""
    cells = np.asarray(cells)
    check_shape(cells, (None, 2), where, kinds="iu")
    return cells.astype(np.int32)


def scene(frames=None, grid: dict | None = None, truth_cells=None) -> RecordedScene:
    """What a recorded trial keeps of a TBD scene: frames (K, H, W), the grid
    (must match the frames) and the true cells (K, 2) (None under the null)."""
    kept = RecordedScene()
    if grid is not None:
        kept.info["grid"] = grid = _grid(grid)
    if frames is not None:
        frames = np.asarray(frames)
        check_shape(frames, (None, None, None), "frames")
        if grid is not None and frames.shape[1:] != (grid["rows"], grid["cols"]):
            raise ValueError(f"TrialRecord.grid: rows x cols = {grid['rows']} x {grid['cols']} "
                             f"does not match frames {frames.shape[1]} x {frames.shape[2]}")
        kept.images["frames"] = frames
    if truth_cells is not None:
        kept.arrays["truth_cells"] = _cells(truth_cells, "truth_cells")
    return kept


def method_trace(threshold: float | None, track_cells=None, value=None, score: float | None = None,
                 image_shape: tuple[int, int] | None = None) -> MethodTrace:
    """What a recorded trial keeps of a TBD method: its backtracked cells (K, 2),
    last-frame value map (H, W) (must be ``image_shape`` when given) and scene score."""
    arrays, images = {}, {}
    if track_cells is not None:
        arrays["track_cells"] = _cells(track_cells, "track_cells")
    if value is not None:
        value = np.asarray(value)
        check_shape(value, image_shape or (None, None), "value")
        images["value"] = value
    return MethodTrace(threshold=threshold, arrays=arrays, images=images,
                       info={} if score is None else {"score": float(score)})


# ------------------------------------------------------------------ what is drawn

def _image_shape(rec: TrialRecord) -> tuple[int, int] | None:
    """(H, W) of the images: from the frames, else the grid, else None."""
    frames = rec.image_shape("frames")
    if frames is not None and len(frames) == 3:
        return frames[1], frames[2]
    grid = rec.info.get("grid")
    return None if grid is None else (int(grid["rows"]), int(grid["cols"]))


def _finite(x) -> bool:
    return x is not None and math.isfinite(x)


def _drawn(tr: MethodTrace, image: tuple | None) -> dict[str, bool]:
    """Which of a method's entities are logged, for the logging and the views alike."""
    score = _finite(tr.info.get("score"))
    return {"score": score, "threshold": score and _finite(tr.threshold),
            "track": "track_cells" in tr.arrays and image is not None, "value": "value" in tr.images}


def _track_path(layout: TrialLayout, m: MethodLayout) -> str:
    return layout.path(f"frames/{m.base.rsplit('/', 1)[-1]}_track")


def _log_grid_axes(stream, path: str, grid: dict) -> None:
    """Axes in metres over the frames: cell (row, col) spans x_min + col·cell .. + cell and
    y_min + row·cell .. + cell, its pixel column col and row rows - 1 - row (north up)."""
    cell, x_min, y_min, rows, cols = (float(grid[key]) for key in ("cell_m", "x_min_m", "y_min_m", "rows", "cols"))
    if not cell > 0:
        return
    extent = np.array([[x_min, y_min], [x_min + cols * cell, y_min + rows * cell]])
    log_axes(stream, path, frame_of(extent), scale=1 / cell, offset=(-x_min / cell, rows + y_min / cell))


def cell_pixels(cells: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Pixel centres ``(col + 0.5, rows - row - 0.5)`` of (row, col) cells in
    the north-up image; NaN rows for cells outside the grid."""
    rows, cols = shape
    r, c = cells[:, 0].astype(np.float64), cells[:, 1].astype(np.float64)
    out = np.column_stack([c + 0.5, rows - r - 0.5]).astype(np.float32)
    out[~((r >= 0) & (r < rows) & (c >= 0) & (c < cols))] = np.nan
    return out


class TBDTask(Task):
    """Track-before-detect: a scene score at a calibrated per-scene Pfa, and a backtracked track."""

    name = TBD
    scene_type = TBDScene
    calibrated = True
    calibration_modes = ("nominal", "empirical", "gumbel", "pot")
    pfa_unit = "per scene"
    noun, short_noun = "track-before-detect", "TBD"
    null_sample = "one scene score per null scene"
    recording_text = ("per TBD method the frames as heatmaps with the true and backtracked tracks, the "
                      "last-frame value map and the scene score against its threshold")
    summary_columns = ("n_trials", "pd", "pd_low", "pd_high", "pfa", "pfa_low", "pfa_high", "rmse_mean",
                       "rmse_low", "rmse_high", "threshold", "realised_snr_db", "rmse_all_mean", "rmse_all_low",
                       "rmse_all_high", "snr_offset_unit_innovation_db")
    headline_columns = ("pd", "pd_low", "pd_high", "pfa", "pfa_low", "pfa_high", "rmse_mean", "rmse_low",
                        "rmse_high")
    recording_charts = (("pd", "Pd"), ("rmse_mean", "RMSE of detected tracks (m)"))
    informative_column = "pd"
    scene_entities = ("frames",)
    ranking_metric = "detected"
    ranking_higher_is_better = True
    ranking_label = "Pd (track detection)"
    ranking_binary = True
    ranking_column = "pd"
    curves = (("pd", "Pd (track detection)"),)
    method_entities = ("score", "threshold", "value")

    # -------------------------------------------------------------- worker side

    def check_output(self, out, batch: Batch) -> TBDOutput:
        if not isinstance(out, TBDOutput):
            raise OutputError(f"expected a TBDOutput, got {type(out).__name__}")
        check_finite("score", np.asarray(out.score, float), (batch.n,))
        track = np.asarray(out.track)
        if track.shape != (batch.n, batch.steps, 2) or not np.issubdtype(track.dtype, np.integer):
            raise OutputError(f"track has shape {track.shape} ({track.dtype}), expected integer cells "
                              f"{(batch.n, batch.steps, 2)}")
        grid = batch.scene.grid
        if track.min() < 0 or (track[..., 0] >= grid.rows).any() or (track[..., 1] >= grid.cols).any():
            raise OutputError("track leaves the grid")
        return out

    def null_values(self, batch: Batch, out: TBDOutput) -> np.ndarray:
        """One scene score per null trial: the calibration sample."""
        return np.asarray(out.score, float)

    def null_cells(self, batch: Batch, out: TBDOutput) -> np.ndarray | None:
        """Order statistics of each null scene's value map (the final merit per
        cell), for the per-cell Pfa (:func:`bench.calibration.cell_calibration`)."""
        return None if out.value is None else cell_order_statistics(out.value)

    def trial_metrics(self, batch: Batch, out: TBDOutput, threshold: float) -> dict[str, np.ndarray]:
        sc = batch.scene
        if sc.target_cells is None:
            raise OutputError("an evaluation batch has no target (target_cells is None)")
        offset = (unit_innovation_snr_offset_db(sc.ar_coefficients, sc.noise_autocovariance)
                  if sc.noise_autocovariance is not None else np.nan)
        return (tbd_trial_metrics(out.score, out.track, threshold, target_cells=sc.target_cells,
                                  truth_xy_m=batch.truth[..., :2], grid=sc.grid.as_dict(),
                                  tolerance_cells=int(sc.hit_tolerance_cells))
                | {"snr_offset_unit_innovation_db": np.full(batch.n, offset)} | time_series(batch))

    def recorded_scene(self, batch: Batch, i: int) -> RecordedScene:
        cells = batch.scene.target_cells
        return scene(batch.z[i], batch.scene.grid.as_dict(), None if cells is None else np.asarray(cells[i]))

    def recorded_method(self, batch: Batch, out: TBDOutput, i: int, threshold: float) -> MethodTrace:
        grid = batch.scene.grid
        return method_trace(threshold, np.asarray(out.track[i]),
                            None if out.value is None else np.asarray(out.value[i]), float(out.score[i]),
                            image_shape=(int(grid.rows), int(grid.cols)))

    # -------------------------------------------------------------- driver side

    def summarise(self, trials: pd.DataFrame, series: dict) -> pd.DataFrame:
        return summarise_tbd(trials, series)

    def apply_calibration(self, summary: pd.DataFrame, trials: pd.DataFrame, cal) -> None:
        """The Pfa columns of a TBD config are the scene Pfa of the threshold
        used, measured on the calibration's null scenes."""
        rows = (summary.scenario == cal.scenario) & (summary.config == cal.method)
        summary.loc[rows, ["pfa", "pfa_low", "pfa_high"]] = [cal.used_pfa, cal.used_pfa_low, cal.used_pfa_high]

    def steps(self, trials: pd.DataFrame, series: dict[str, np.ndarray]) -> pd.DataFrame:
        """Per frame: position RMSE over detected trials and over every trial."""
        detected = trials["detected"].to_numpy(bool)
        return pd.DataFrame({"rmse_position": per_step_rmse(series["sq_err_m2"][detected]),
                             "n_trials": int(detected.sum()),
                             "rmse_position_all": per_step_rmse(series["sq_err_m2"])})

    def log_trial(self, stream, layout: TrialLayout, rec: TrialRecord) -> None:
        t = np.asarray(rec.t, dtype=np.float64)
        image = _image_shape(rec)
        if "frames" in rec.images:
            self._log_frames(stream, layout, rec, t, image)
        for m in layout.methods_of(self):
            self._log_method(stream, layout, m, rec.methods[m.label], t, image)

    @staticmethod
    def _log_frames(stream, layout: TrialLayout, rec: TrialRecord, t: np.ndarray, image) -> None:
        """The frames as one image column, then the true cells over them."""
        q = rec.quantised("frames")
        if q.codes.shape[0] == 0 or q.codes.size == 0:
            return
        grid = rec.info.get("grid")
        log_image_series(stream, layout.path("frames"), q, t, _FRAMES_COLORMAP,
                         None if grid is None else {f"grid_{k}": v for k, v in grid.items()})
        if grid is not None and all(key in grid for key in GRID_KEYS):
            _log_grid_axes(stream, layout.path("frames/axes"), grid)
        if "truth_cells" in rec.arrays and image is not None:
            log_track(stream, layout.path("frames/truth_track"), t, cell_pixels(rec.arrays["truth_cells"], image),
                      TRUTH_COLOR, radius=3.0, label="truth", label_at=layout.label_at())

    @staticmethod
    def _log_method(stream, layout: TrialLayout, m: MethodLayout, tr: MethodTrace, t: np.ndarray, image) -> None:
        import rerun as rr

        k, drawn = t.shape[0], _drawn(tr, image)
        every = np.arange(k)
        if drawn["score"]:
            # A scene-level number: a flat line, to compare with the threshold.
            log_series(stream, m.path("score"), t, every, np.full(k, tr.info["score"]),
                       rr.SeriesLines(names=f"{m.label} score", colors=[m.color], widths=[2.0]))
        if drawn["threshold"]:
            log_series(stream, m.path("threshold"), t, every, np.full(k, tr.threshold),
                       rr.SeriesLines(names=f"{m.label} threshold", colors=[(*m.color, 150)], widths=[1.0]))
        if drawn["track"]:
            log_track(stream, _track_path(layout, m), t, cell_pixels(tr.arrays["track_cells"], image), m.color,
                      radius=3.0, label=m.label, label_at=layout.label_at(m))
        if drawn["value"]:
            log_image(stream, m.path("value"), tr.quantised("value"), _VALUE_COLORMAP)

    def views(self, layout: TrialLayout, rec: TrialRecord) -> Views:
        """The frames with every track and each value map with its method's
        track on top; the scores against their thresholds below."""
        import rerun.blueprint as rrb

        origin, image = rerun_path(layout.root), _image_shape(rec)
        images = ([rrb.Spatial2DView(origin=rerun_path(layout.path("frames")), name="frames (north up)")]
                  if "frames" in rec.images else [])
        scores = []
        for m in layout.methods_of(self):
            drawn = _drawn(rec.methods[m.label], image)
            if drawn["value"]:
                contents = [relative(layout, m.path("value")),
                            relative(layout, m.path(f"value/{COLOUR_SCALE}")) + "/**"] + (
                    [relative(layout, _track_path(layout, m)) + "/**"] if drawn["track"] else [])   # with its label
                images.append(rrb.Spatial2DView(origin=origin, name=f"{m.label} value", contents=contents))
            scores += [relative(layout, m.path(c)) for c in ("score", "threshold") if drawn[c]]
        top = [rrb.Grid(*images) if len(images) > 3 else rrb.Horizontal(*images)] if images else []
        bottom = ([rrb.TimeSeriesView(origin=origin, name="scores", contents=scores, axis_x=trial_time_axis(layout))]
                  if scores else [])
        return Views(top=top, bottom=bottom, draws_scene=bool(images))

    def report_sections(self, ctx: ReportContext) -> list[str]:
        from radarbench.bench.tasks.tbd import report
        return report.sections(ctx)
