"""Logging a recorded trial into a Rerun stream, shared by the file and the live viewer.

The harness draws what every task shares: the true track, the measurements
and each method's extra series; every task then draws its own part of the
trial (``Task.log_trial``) with the primitives below (docs/architecture.md,
'Recordings').

Conventions every primitive keeps:

* Timelines: every time series carries ``step`` (sequence, 0..K-1) and
  ``time`` (duration, seconds, from ``t``). Whole-track lines, images of one
  instant and summaries are static, so they show on any timeline.
* Orientation: Rerun's 2D views draw +y downwards. Positions are logged with
  **y negated** so that north (+y) is up on screen (:func:`north_up`); anyone
  reading positions back must negate y again.
* Whole series are sent with ``send_columns`` (one call per entity, not one
  ``log`` per sample: ~500x faster), and a zero-length column is never sent
  (the 0.41 viewer panics on empty chunks).

Entity paths under a trial root ``/{scenario}/snr_{±NN}dB/trial_{NNN}``::

    .../axes                    static LineStrips2D: the track view's axis lines and ticks
    .../axes/labels             static Points2D: tick values and axis titles (bench.recording.axes)
    .../truth                   Points2D per step + static LineStrips2D (whole track)
    .../truth/label             static Points2D naming it (log_label; every track drawn has one)
    .../measurements            Points2D per step (missing rows skipped)
    .../measurements/all        static Points2D of every measurement
    .../{method}/{trace}        Scalars (extra series: whitened innovation, error_x, ...)

Every image drawn by :func:`log_image` / :func:`log_image_series` gets a colour scale
(:func:`log_colour_scale`) under ``{image}/colour_scale``.

rerun is imported inside the functions: importing this module stays cheap.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from radarbench.bench.recording.axes import DRAWABLE_MAX, log_axes
from radarbench.bench.recording.blueprint import TrialTab
from radarbench.bench.recording.layout import AXES, MEASUREMENT_COLOR, NEUTRAL_COLOR, TRUTH_COLOR, TrialLayout
from radarbench.bench.recording.paths import rerun_path
from radarbench.bench.recording.record import Quantised, TrialRecord

__all__ = ["COLOUR_SCALE", "FLUSH_EVERY", "LABEL", "indexes", "log_colour_scale", "log_image", "log_image_series",
           "log_label", "log_points", "log_record", "log_records",
           "log_series", "log_static_points", "log_track", "north_up", "quant_info"]

#: Records logged between two flushes: the file sink queue is unbounded.
FLUSH_EVERY = 50


def indexes(steps: np.ndarray, t: np.ndarray) -> list:
    """``step`` and ``time`` time columns for the given step indices."""
    import rerun as rr

    return [
        rr.TimeColumn("step", sequence=steps.astype(np.int64)),
        rr.TimeColumn("time", duration=np.asarray(t, dtype=np.float64)[steps]),
    ]


def north_up(xy: np.ndarray) -> np.ndarray:
    """Negate y: 2D views draw +y downwards, radar plots have north up. A coordinate a
    float32 cannot hold (a diverged estimate) is NaN, a gap in the drawing, rather than an
    overflow to inf."""
    xy = np.asarray(xy, np.float64)
    drawable = np.where(np.abs(xy) <= DRAWABLE_MAX, xy, np.nan)
    return np.column_stack([drawable[:, 0], -drawable[:, 1]]).astype(np.float32)


def log_series(stream, path: str, t: np.ndarray, steps: np.ndarray, values: np.ndarray, style) -> None:
    """Static styling plus one ``send_columns`` for a scalar series at ``steps``."""
    import rerun as rr

    if steps.size == 0:
        return  # empty chunks crash the 0.41 viewer
    path = rerun_path(path)
    stream.log(path, style, static=True)
    stream.send_columns(
        path, indexes=indexes(steps, t),
        columns=rr.Scalars.columns(scalars=np.asarray(values, dtype=np.float64)),
    )


def log_points(stream, path: str, t: np.ndarray, pos: np.ndarray, color, radius: float,
               label: str | None = None) -> np.ndarray:
    """One Points2D per step with finite (screen) coordinates, named ``label`` beside the
    point on the plot; returns those steps."""
    import rerun as rr

    steps = np.flatnonzero(np.isfinite(pos).all(axis=1))
    if steps.size == 0:
        return steps
    path = rerun_path(path)
    ui = rr.components.Radius.ui_points(radius)
    stream.log(path, rr.Points2D.from_fields(colors=[color], radii=[ui], **_shown(label)), static=True)
    stream.send_columns(
        path, indexes=indexes(steps, t),
        columns=rr.Points2D.columns(positions=pos[steps]),
    )
    return steps


def log_track(stream, path: str, t: np.ndarray, pos: np.ndarray, color, radius: float = 5.0,
              label: str | None = None, label_at: float = 1.0) -> None:
    """Current position per step plus the whole track as a static line
    (``pos`` in screen coordinates: north-up metres or image pixels), named ``label`` on
    the plot at a share ``label_at`` of its points (:func:`log_label`)."""
    import rerun as rr

    steps = log_points(stream, path, t, pos, color, radius=radius)
    if steps.size:
        stream.log(
            rerun_path(path),
            rr.LineStrips2D([pos[steps]], colors=[color], radii=[rr.components.Radius.ui_points(1.0)]),
            static=True,
        )
        if label is not None:
            log_label(stream, path, pos[steps], color, label, label_at)


#: The child of a drawn series that names it on a 2-D plot (:func:`log_label`).
LABEL = "label"


def log_label(stream, path: str, pos: np.ndarray, color, label: str, at: float = 1.0) -> None:
    """The 2-D views' legend (they have none): a static point in the series' colour with
    its ``label``, at the point a share ``at`` along the series' drawn points ``pos``
    (N, 2) (1: the last; :meth:`TrialLayout.label_at` spreads overlapping tracks' names),
    under ``path/label``: one name per series, where the line is, not at its centre."""
    import rerun as rr

    point = pos[round(float(np.clip(at, 0.0, 1.0)) * (len(pos) - 1))]
    stream.log(rerun_path(f"{path}/{LABEL}"),
               rr.Points2D([point], colors=[color], radii=[rr.components.Radius.ui_points(3.5)],
                           **_shown(label)), static=True)


def _shown(label: str | None) -> dict:
    """The fields that name a 2-D entity on the plot (each point's label under it)."""
    return {} if label is None else {"labels": [label], "show_labels": True}


def log_static_points(stream, path: str, pos: np.ndarray, color, radius: float, label: str | None = None) -> None:
    """Static Points2D (a cloud that shows on every step), named ``label`` on the plot."""
    import rerun as rr

    stream.log(rerun_path(path), rr.Points2D(pos, colors=[color], radii=[rr.components.Radius.ui_points(radius)],
                                             **_shown(label)), static=True)


def quant_info(q: Quantised, extra: dict | None = None):
    """Static AnyValues explaining the codes of a quantised image (north up)."""
    import rerun as rr

    info = {"code_lo": q.lo, "code_hi": q.hi,
            "codes": "0 = non-finite; value = code_lo + (code - 1) * (code_hi - code_lo) / 254",
            "orientation": "north up: grid row r is image row rows-1-r"}
    info.update(extra or {})
    return rr.AnyValues(**info)


def log_image(stream, path: str, q: Quantised, colormap: str) -> None:
    """A static image of codes (rows flipped: north up), with its code range."""
    import rerun as rr

    if q.codes.size == 0:
        return
    log_colour_scale(stream, path, q, colormap)
    path = rerun_path(path)
    stream.log(path, rr.DepthImage(np.ascontiguousarray(q.codes[::-1, :]), colormap=colormap,
                                   depth_range=(1.0, 255.0), meter=1.0), static=True)
    stream.log(path, quant_info(q), static=True)


#: Entity under an image that holds its colour scale (a bar beside it, with its values).
COLOUR_SCALE = "colour_scale"


def log_colour_scale(stream, image_path: str, q: Quantised, colormap: str) -> None:
    """A colour scale for the image at ``image_path``: a vertical bar of the codes
    1..255 in the same colormap, right of the image (``q.codes``: (H, W) or (K, H, W)),
    labelled with the values at its top, middle and bottom (``q.lo``..``q.hi``)."""
    import rerun as rr

    height, width = int(q.codes.shape[-2]), int(q.codes.shape[-1])
    if height == 0 or width == 0:
        return
    bar_w, gap = max(2, width // 25), max(1, width // 50)
    column = np.linspace(255.0, 1.0, height).round().astype(np.uint8)   # top: the highest value
    bar = np.ascontiguousarray(np.repeat(column[:, None], bar_w, axis=1))
    path = rerun_path(f"{image_path}/{COLOUR_SCALE}")
    stream.log(path, rr.Transform3D(translation=[float(width + gap), 0.0, 0.0]), static=True)
    stream.log(path, rr.DepthImage(bar, colormap=colormap, depth_range=(1.0, 255.0), meter=1.0), static=True)
    values = (q.hi, (q.lo + q.hi) / 2, q.lo)
    stream.log(rerun_path(f"{image_path}/{COLOUR_SCALE}/values"),
               rr.Points2D([[bar_w + 0.5, 0.5], [bar_w + 0.5, height / 2], [bar_w + 0.5, height - 0.5]],
                           labels=[f"{v:.3g}" for v in values], radii=[rr.components.Radius.ui_points(0.5)],
                           colors=[NEUTRAL_COLOR], show_labels=True), static=True)


def log_image_series(stream, path: str, q: Quantised, t: np.ndarray, colormap: str, extra: dict | None = None) -> None:
    """One image per step (codes (K, H, W), rows flipped: north up) as one
    column, with its code range and ``extra`` static values."""
    import rerun as rr

    k = q.codes.shape[0]
    if k == 0 or q.codes.size == 0:
        return
    log_colour_scale(stream, path, q, colormap)
    path = rerun_path(path)
    fmt = rr.components.ImageFormat(width=int(q.codes.shape[2]), height=int(q.codes.shape[1]),
                                    channel_datatype=rr.ChannelDatatype.U8)
    stream.log(path, rr.DepthImage.from_fields(format=fmt, colormap=colormap, depth_range=(1.0, 255.0),
                                               meter=1.0), static=True)
    stream.log(path, quant_info(q, extra), static=True)
    codes = np.ascontiguousarray(q.codes[:, ::-1, :]).reshape(k, -1)
    stream.send_columns(path, indexes=indexes(np.arange(k), t), columns=rr.DepthImage.columns(buffer=codes))


def _log_measurements(stream, layout: TrialLayout, t: np.ndarray, xy: np.ndarray) -> None:
    """Current measurement per step, and all of them as a static cloud."""
    pos = north_up(xy)
    # Named at the current one: the faded cloud's label would be faded too.
    steps = log_points(stream, layout.path("measurements"), t, pos, MEASUREMENT_COLOR, radius=4.0,
                       label="measurement")
    if steps.size:
        # A child entity: static positions on `measurements` itself would
        # shadow the per-step ones.
        log_static_points(stream, layout.path("measurements/all"), pos[steps], (*MEASUREMENT_COLOR, 110), 2.0)


def _log_traces(stream, layout: TrialLayout, rec: TrialRecord, t: np.ndarray) -> None:
    import rerun as rr

    every = np.arange(t.shape[0])
    for m in layout.methods:
        for key, path in m.traces.items():
            log_series(stream, path, t, every, rec.methods[m.label].traces[key],
                       rr.SeriesLines(names=f"{m.label} {key}", colors=[m.color], widths=[1.0]))


def log_record(rec: TrialRecord, stream, tab: TrialTab) -> None:
    """Log one trial: the harness's part (with its track view's axes), then each task's."""
    layout = tab.layout
    t = np.asarray(rec.t, dtype=np.float64)
    if tab.frame is not None:
        log_axes(stream, layout.path(AXES), tab.frame)
    if rec.truth_xy is not None:
        log_track(stream, layout.path("truth"), t, north_up(rec.truth_xy), TRUTH_COLOR, label="truth",
                  label_at=layout.label_at())
    if rec.measurements_xy is not None:
        _log_measurements(stream, layout, t, rec.measurements_xy)
    for task in layout.tasks:
        task.log_trial(stream, layout, rec)
    _log_traces(stream, layout, rec, t)


def log_records(records: Iterable[TrialRecord], stream, tabs: Iterable[TrialTab]) -> None:
    """Log records (``tabs``: theirs, :func:`bench.recording.blueprint.trial_tab`), flushing
    every FLUSH_EVERY (and after every record with images: megabytes each) to keep the
    sink queue short."""
    for i, (rec, tab) in enumerate(zip(records, tabs), start=1):
        log_record(rec, stream, tab)
        if i % FLUSH_EVERY == 0 or rec.has_images():
            stream.flush()
