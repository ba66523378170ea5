"""What a recorded map keeps and how it is drawn in Rerun (the cell-detection task;
docs/architecture.md, 'Recordings').

Images are drawn with range up (map row r at image row R - 1 - r, like the
TBD frames' north up) and Doppler across (column d, zero Doppler at D // 2);
a cell (r, d) is at pixel (d + 0.5, R - r - 0.5) (:func:`bench.tasks.tbd.cell_pixels`).
The entities are listed in :mod:`bench.tasks.cells`. Worker side
(:func:`recorded_scene`, :func:`recorded_method`) imports no rerun.
"""

from __future__ import annotations

import numpy as np

from radarbench.bench.recording.blueprint import Views, relative
from radarbench.bench.recording.layout import TRUTH_COLOR, TrialLayout
from radarbench.bench.recording.paths import rerun_path
from radarbench.bench.recording.record import MethodTrace, TrialRecord
from radarbench.bench.tasks.base import RecordedScene
from radarbench.bench.tasks.cells.metrics import declared_cells
from radarbench.bench.tasks.tbd import cell_pixels

_MAP_COLORMAP = "viridis"
_STATISTIC_COLORMAP = "inferno"
#: one colour per region label, in REGION_NAMES order (homogeneous grey, Bragg blue,
#: interference orange, clutter edge green; its quiet side light, its raised side dark green)
_REGION_COLORS = [(90, 90, 90), (60, 120, 230), (240, 150, 40), (60, 190, 90), (150, 230, 140), (20, 120, 50)]


def _db(power: np.ndarray) -> np.ndarray:
    return (10.0 * np.log10(np.maximum(np.asarray(power, np.float64), 1e-30))).astype(np.float32)


def recorded_scene(batch, i: int) -> RecordedScene:
    """Map ``i``: the RD map and the true noise power in dB (images), the
    region labels (exact, (1, R, D)) and the target cells ((1, T, 2))."""
    sc = batch.scene
    return RecordedScene(
        arrays={"regions": np.asarray(sc.region_labels, np.int8)[None],
                "target_cells": np.asarray(sc.target_cells[i], np.int32)[None]},
        images={"rd_map_db": _db(batch.z[i, 0]), "noise_power_db": _db(sc.noise_power[i])},
        info={"region_names": list(sc.region_names)})


def recorded_method(batch, out, i: int, threshold: float) -> MethodTrace:
    """A detector on map ``i``: its statistic (image), its detections (exact
    cells, (1, M, 2)) and, when it gives its noise estimate and threshold
    factor, its threshold map in dB at the threshold in force."""
    stat = np.asarray(out.statistic[i])
    declared = np.argwhere(declared_cells(stat, threshold)) if np.isfinite(threshold) else np.zeros((0, 2), np.int64)
    images = {"statistic": stat.astype(np.float32)}
    nominal_pfa = 10.0 ** (-threshold) if np.isfinite(threshold) else np.nan
    # the threshold in force as a nominal Pfa; a calibrated threshold at or below 0 (or above
    # ~308) has none in (0, 1), where the closed forms for K are defined: no threshold map then
    if out.noise_estimate is not None and out.threshold_factor is not None and 0.0 < nominal_pfa < 1.0:
        factor = np.asarray(out.threshold_factor(nominal_pfa), np.float64)
        images["threshold_map_db"] = _db(np.asarray(out.noise_estimate[i], np.float64) * factor)
    return MethodTrace(threshold=threshold, arrays={"detections": declared.astype(np.int32)[None]}, images=images)


def _shape(rec: TrialRecord) -> tuple[int, int] | None:
    shape = rec.image_shape("rd_map_db")
    return None if shape is None else (int(shape[0]), int(shape[1]))


def _log_cells(stream, path: str, cells: np.ndarray, shape, color, radius: float) -> None:
    import rerun as rr

    if cells.size == 0 or shape is None:
        return
    stream.log(rerun_path(path), rr.Points2D(cell_pixels(cells, shape), colors=[color],
                                             radii=[rr.components.Radius.ui_points(radius)]), static=True)


def log_trial(task, stream, layout: TrialLayout, rec: TrialRecord) -> None:
    """The map, its regions and targets; per detector its statistic, threshold map and detections."""
    import rerun as rr

    from radarbench.bench.recording.draw import log_image

    shape = _shape(rec)
    if "rd_map_db" in rec.images:
        log_image(stream, layout.path("map"), rec.quantised("rd_map_db"), _MAP_COLORMAP)
    if "noise_power_db" in rec.images:
        log_image(stream, layout.path("noise_power"), rec.quantised("noise_power_db"), _MAP_COLORMAP)
    if "regions" in rec.arrays:
        names = rec.info.get("region_names", [])
        labels = np.ascontiguousarray(rec.arrays["regions"][0][::-1, :]).astype(np.uint8)
        path = rerun_path(layout.path("regions"))
        stream.log(path, rr.AnnotationContext([(k, name, _REGION_COLORS[k % len(_REGION_COLORS)])
                                               for k, name in enumerate(names)]), static=True)
        stream.log(path, rr.SegmentationImage(labels), static=True)
    if "target_cells" in rec.arrays:
        _log_cells(stream, layout.path("map/targets"), rec.arrays["target_cells"][0], shape, TRUTH_COLOR, 4.0)
    for m in layout.methods_of(task):
        tr = rec.methods[m.label]
        if "statistic" in tr.images:
            log_image(stream, m.path("statistic"), tr.quantised("statistic"), _STATISTIC_COLORMAP)
        if "threshold_map_db" in tr.images:
            log_image(stream, m.path("threshold_map"), tr.quantised("threshold_map_db"), _MAP_COLORMAP)
        if "detections" in tr.arrays:
            _log_cells(stream, m.path("detections"), tr.arrays["detections"][0], shape, m.color, 2.5)


def views(task, layout: TrialLayout, rec: TrialRecord) -> Views:
    """The map with the targets and every detector's detections on top, the
    regions; below, per detector its statistic and its threshold map."""
    import rerun.blueprint as rrb

    origin = rerun_path(layout.root)
    methods = layout.methods_of(task)
    detections = [relative(layout, m.path("detections")) for m in methods if "detections" in rec.methods[m.label].arrays]
    top = []
    if "rd_map_db" in rec.images:
        top.append(rrb.Spatial2DView(origin=origin, name="RD map (dB), targets, detections",
                                     contents=[relative(layout, layout.path("map")),
                                               relative(layout, layout.path("map/targets")), *detections]))
    if "regions" in rec.arrays:
        top.append(rrb.Spatial2DView(origin=origin, name="clutter regions",
                                     contents=[relative(layout, layout.path("regions")),
                                               relative(layout, layout.path("map/targets"))]))
    bottom = []
    for m in methods:
        tr = rec.methods[m.label]
        for image, title in (("statistic", "statistic"), ("threshold_map_db", "threshold map (dB)")):
            if image in tr.images:
                child = "statistic" if image == "statistic" else "threshold_map"
                bottom.append(rrb.Spatial2DView(origin=origin, name=f"{m.label} {title}",
                                                contents=[relative(layout, m.path(child)),
                                                          relative(layout, m.path("detections"))]))
    bottom = [rrb.Grid(*bottom)] if len(bottom) > 3 else bottom
    return Views(top=[rrb.Horizontal(*top)] if top else [], bottom=bottom, draws_scene=True)
