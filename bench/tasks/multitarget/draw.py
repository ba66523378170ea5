"""How a recorded multi-target trial is drawn in Rerun (docs/architecture.md,
'Recordings'); driver side, rerun imported inside the functions.

Entities under the trial root (positions in metres, north up)::

    .../truths/target_{t}       the true track of target t: Points2D per scan + static LineStrips2D
    .../plots                   every plot of the scan, Points2D per scan: target-originated
                                green, clutter grey
    .../{method}/tracks         the method's tracks at the scan, Points2D labelled by identity:
                                confirmed in the method's colour, tentative faded, terminated red
    .../{method}/gates          3-sigma position ellipses of the tracks (LineStrips2D per scan)
    .../{method}/track_lines    static LineStrips2D: each confirmed track's path (the method named
                                on its longest, ``track_lines/label``)
    .../{method}/{trace}        Scalars per scan: GOSPA (m), confirmed tracks (drawn by the harness)
"""

from __future__ import annotations

import numpy as np

from radarbench.bench.recording.draw import indexes, log_label, log_track, north_up
from radarbench.bench.recording.layout import TRUTH_COLOR, TrialLayout
from radarbench.bench.recording.paths import rerun_path
from radarbench.bench.recording.record import MethodTrace, TrialRecord

TARGET_PLOT_COLOR = (60, 220, 90)
CLUTTER_COLOR = (150, 150, 150)
TERMINATED_COLOR = (230, 60, 60)
#: gate radius: sqrt of the chi-square (2 dof) 0.989 quantile
GATE_SIGMAS = 3.0
_ELLIPSE = np.stack([np.cos(np.linspace(0, 2 * np.pi, 25)), np.sin(np.linspace(0, 2 * np.pi, 25))], axis=1)


def _screen(xy: np.ndarray) -> np.ndarray:
    """(..., 2) positions north up (y negated), float32."""
    out = np.asarray(xy, np.float32).copy()
    out[..., 1] *= -1
    return out


def _log_point_sets(stream, path: str, t: np.ndarray, xy: np.ndarray, colors: np.ndarray, radius: float,
                    labels: np.ndarray | None = None) -> None:
    """Per scan the finite points of ``xy`` (K, P, 2) with ``colors`` (K, P, 4)
    as one column partitioned by scan (an empty scan clears the previous one)."""
    import rerun as rr

    ok = np.isfinite(xy).all(axis=-1)
    lengths = ok.sum(axis=1)
    if lengths.sum() == 0:
        return
    path = rerun_path(path)
    stream.log(path, rr.Points2D.from_fields(radii=[rr.components.Radius.ui_points(radius)]), static=True)
    fields = {"positions": _screen(xy[ok]), "colors": colors[ok]}
    if labels is not None:
        fields["labels"] = [str(v) for v in labels[ok]]
    stream.send_columns(path, indexes=indexes(np.arange(len(t)), t),
                        columns=rr.Points2D.columns(**fields).partition(lengths))


def log_scene(stream, layout: TrialLayout, rec: TrialRecord) -> None:
    """The true tracks and the plots of every scan, coloured by origin."""
    t = np.asarray(rec.t, dtype=np.float64)
    truths = rec.arrays.get("truths_xy")
    if truths is not None:
        for j in range(truths.shape[1]):
            log_track(stream, layout.path(f"truths/target_{j}"), t, north_up(truths[:, j]), TRUTH_COLOR, radius=4.0,
                      label=f"target {j}")
    log_plots(stream, layout.path("plots"), t, rec.arrays.get("plots_xy"), rec.arrays.get("plot_origin"))


def log_plots(stream, path: str, t: np.ndarray, plots: np.ndarray | None, origin: np.ndarray | None) -> None:
    """Plots (K, P, 2) per scan at ``path``, coloured by origin (target green, clutter grey)."""
    if plots is not None and origin is not None:
        colors = np.where((origin >= 0)[..., None], (*TARGET_PLOT_COLOR, 255), (*CLUTTER_COLOR, 200)).astype(np.uint8)
        _log_point_sets(stream, path, t, plots, colors, 2.5)


def _gate(center: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """(25, 2) the GATE_SIGMAS ellipse of a 2x2 covariance."""
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    return center + GATE_SIGMAS * (_ELLIPSE * np.sqrt(np.maximum(w, 0.0))) @ v.T


def log_method(stream, layout: TrialLayout, m, tr: MethodTrace, t: np.ndarray) -> None:
    """A method's tracks per scan (coloured by status, labelled by identity), their gates and the
    paths of its confirmed tracks."""
    import rerun as rr

    xy, ids, status = tr.arrays.get("track_xy"), tr.arrays.get("track_id"), tr.arrays.get("track_status")
    if xy is None:
        return
    shade = {1: (*m.color, 90), 2: (*m.color, 255), 3: (*TERMINATED_COLOR, 255)}
    colors = np.zeros((*status.shape, 4), np.uint8)
    for code, rgba in shade.items():
        colors[status == code] = rgba
    occupied = status > 0
    shown = np.where(occupied[..., None], xy, np.nan)
    _log_point_sets(stream, m.path("tracks"), t, shown, colors, 3.5, labels=ids)
    cov = tr.arrays.get("track_cov")
    if cov is not None:
        k_idx, j_idx = np.nonzero(occupied & np.isfinite(cov).all(axis=(-1, -2)))
        if k_idx.size:
            strips = [_screen(_gate(xy[k, j], cov[k, j])) for k, j in zip(k_idx, j_idx)]
            path = rerun_path(m.path("gates"))
            stream.log(path, rr.LineStrips2D.from_fields(colors=[(*m.color, 160)],
                                                         radii=[rr.components.Radius.ui_points(0.75)]), static=True)
            stream.send_columns(path, indexes=indexes(np.arange(len(t)), t),
                                columns=rr.LineStrips2D.columns(strips=strips).partition(
                                    np.bincount(k_idx, minlength=len(t))))
    confirmed = status == 2
    lines = [_screen(xy[confirmed & (ids == i)]) for i in np.unique(ids[confirmed])]
    if lines:
        stream.log(rerun_path(m.path("track_lines")),
                   rr.LineStrips2D(lines, colors=[m.color], radii=[rr.components.Radius.ui_points(1.0)]), static=True)
        # the method named once, on its longest track
        log_label(stream, m.path("track_lines"), max(lines, key=len), m.color, m.label, layout.label_at(m))
