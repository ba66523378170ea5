"""How a recorded detect-and-track trial is drawn in Rerun (docs/architecture.md,
'Recordings'); driver side, rerun imported inside the functions.

Besides the multi-target task's entities (:mod:`bench.tasks.multitarget.draw`: the true
tracks, each chain's plots in the plane, tracks, gates, track lines)::

    .../maps                    DepthImage per scan: the range-Doppler map in dB (range up,
                                Doppler across), with its colour scale
    .../{method}/detections     Points2D per scan over the map: the cells the chain declared

so the maps, the detections, the plots and the tracks share the scan timeline.
"""

from __future__ import annotations

import numpy as np

from radarbench.bench.recording.blueprint import Views, relative
from radarbench.bench.recording.draw import COLOUR_SCALE, indexes, log_image_series
from radarbench.bench.recording.layout import TrialLayout
from radarbench.bench.recording.paths import rerun_path
from radarbench.bench.recording.record import TrialRecord
from radarbench.bench.tasks.multitarget import draw as multitarget_draw
from radarbench.bench.tasks.tbd import cell_pixels

MAPS = "maps"
_MAP_COLORMAP = "viridis"


def map_db(maps: np.ndarray) -> np.ndarray:
    """(K, R, D) float32 power in dB (the recorded maps)."""
    return (10.0 * np.log10(np.maximum(np.asarray(maps, np.float64), 1e-30))).astype(np.float32)


def _log_detections(stream, path: str, t: np.ndarray, cells: np.ndarray, shape: tuple[int, int], color) -> None:
    """Per scan the declared cells (K, P, 2) (-1 padded) as points over the map's pixels."""
    import rerun as rr

    used = cells[..., 0] >= 0
    if not used.any():
        return
    path = rerun_path(path)
    stream.log(path, rr.Points2D.from_fields(radii=[rr.components.Radius.ui_points(3.0)], colors=[color]),
               static=True)
    stream.send_columns(path, indexes=indexes(np.arange(len(t)), t),
                        columns=rr.Points2D.columns(positions=cell_pixels(cells[used], shape)).partition(
                            used.sum(axis=1)))


def log_trial(task, stream, layout: TrialLayout, rec: TrialRecord) -> None:
    t = np.asarray(rec.t, dtype=np.float64)
    q = rec.quantised(MAPS)
    shape = None
    if q is not None and q.codes.size:
        log_image_series(stream, layout.path(MAPS), q, t, _MAP_COLORMAP)
        shape = tuple(int(s) for s in q.codes.shape[1:])
    multitarget_draw.log_scene(stream, layout, rec)
    for m in layout.methods_of(task):
        tr = rec.methods[m.label]
        if shape is not None and "plot_cells" in tr.arrays:
            _log_detections(stream, m.path("detections"), t, tr.arrays["plot_cells"], shape, m.color)
        multitarget_draw.log_plots(stream, m.path("plots"), t, tr.arrays.get("plots_xy"), tr.arrays.get("plot_origin"))
        multitarget_draw.log_method(stream, layout, m, tr, t)


def views(task, layout: TrialLayout, rec: TrialRecord) -> Views:
    """The maps with every chain's detections over them, beside the plane's track view."""
    import rerun.blueprint as rrb

    xy = tuple(rec.arrays[name] for name in ("truths_xy",) if name in rec.arrays)
    top = []
    if MAPS in rec.images:
        contents = [relative(layout, layout.path(MAPS)), relative(layout, layout.path(f"{MAPS}/{COLOUR_SCALE}")) + "/**",
                    *(relative(layout, m.path("detections")) for m in layout.methods_of(task))]
        top.append(rrb.Spatial2DView(origin=rerun_path(layout.root), name="range-Doppler maps (range up)",
                                     contents=contents))
    return Views(top=top, has_xy=bool(xy), xy=xy)
