"""Rerun recordings of selected trials (DESIGN.md section 9).

Workers build one :class:`TrialRecord` per selected trial (``[record] trials``
per SNR); it travels to the driver as bytes (:meth:`TrialRecord.to_bytes`, also
what the SQLite store keeps) and the driver alone writes the recording, either
to a file (:func:`write_recording`) or to a spawned viewer
(:class:`LiveViewer`). Both go through the same ``_log_record``.

Entity paths (readable form; ``{method}`` is :func:`entity_name` of the method
config label)::

    /{scenario}/snr_{±NN}dB/trial_{NNN}/truth               Points2D per step + static LineStrips2D (whole track)
    .../measurements                                          Points2D per step (missing rows skipped)
    .../measurements/all                                      static Points2D of every measurement
    .../{method}/statistic                                    Scalars
    .../{method}/threshold                                    Scalars, the threshold in force at every step
    .../{method}/alarms                                       Scalars at alarm steps only (the statistic there), drawn as points
    .../{method}/{trace}                                      Scalars (extra series, e.g. whitened innovation)
    .../{method}/estimate                                     like truth (trackers)
    /summary/pd_vs_snr/{method}                               static BarChart of Pd (abscissa = SNR, dB)
    /summary/table                                            static TextDocument (Markdown)

SNR parts: ``snr_+05dB``, ``snr_-05dB``, ``snr_+02p5dB`` (non-integer SNR; ``p``
stands for the decimal point), ``null`` for null-hypothesis trials. Rerun keeps
paths in an escaped canonical form in which ``+`` becomes ``\\+``
(``/cv-turn-cv/snr_\\+05dB/trial_000``); the viewer shows the readable form.
:func:`rerun_path` converts a readable path to the canonical one, which is
what :class:`rerun.chunk.RrdReader` returns.

Timelines: every time series carries ``step`` (sequence, 0..K-1) and ``time``
(duration, seconds, from ``t``). Summary data is static, so it shows whatever
timeline is selected.

Orientation: Rerun's 2D views draw +y downwards. Positions are logged with
**y negated** so that north (+y) is up on screen; x is unchanged. Anyone
reading positions back from the file must negate y again.

Whole series are sent with ``send_columns`` (one call per entity, not one
``log`` per sample: ~500x faster), and a zero-length column is never sent (the
0.41 viewer panics on empty chunks).
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import os
import re
import shutil
import socket
import sys
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

# rerun (and pandas) are imported inside the functions that need them: workers
# import this module only for TrialRecord, and `import rerun` costs ~0.5 s.
if TYPE_CHECKING:  # pragma: no cover - typing only
    import pandas as pd
    import rerun as rr

__all__ = [
    "MethodTrace",
    "TrialRecord",
    "LiveViewer",
    "entity_name",
    "method_entity_names",
    "snr_part",
    "entity_root",
    "rerun_path",
    "write_recording",
    "MAX_TABS",
]

#: Trials that get their own tab in the default blueprint; more tabs are unusable.
MAX_TABS = 12
#: Records logged between two flushes: the file sink queue is unbounded.
FLUSH_EVERY = 50
#: Bumped when the byte layout of :meth:`TrialRecord.to_bytes` changes.
_FORMAT_VERSION = 1
#: Children of a method entity that traces must not shadow.
_RESERVED = frozenset({"statistic", "threshold", "alarms", "estimate"})

# tab10: distinct on the viewer's dark background.
_PALETTE = [
    (31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
    (140, 86, 75), (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207),
]
_TRUTH_COLOR = (230, 230, 230)
_MEASUREMENT_COLOR = (255, 200, 60)


# --------------------------------------------------------------------------
# Data carried from workers to the driver
# --------------------------------------------------------------------------


@dataclass(eq=False)
class MethodTrace:
    """What one method config produced on one recorded trial.

    statistic : (K,) float — detector statistic (``None`` for trackers).
    threshold : float — the threshold in force (nominal or calibrated);
        ``None`` or non-finite: not drawn.
    alarms : (K,) bool — ``statistic >= threshold`` as the harness decided it.
    traces : name -> (K,) float — extra series (e.g. whitened innovation).
    estimate_xy : (K, 2) float or None — position estimate, metres (trackers).
    """

    statistic: np.ndarray | None
    threshold: float | None
    alarms: np.ndarray | None
    traces: dict[str, np.ndarray] = field(default_factory=dict)
    estimate_xy: np.ndarray | None = None

    def __post_init__(self) -> None:
        # Normalise types here so the byte round trip is exact whatever the
        # worker passed (lists, numpy scalars, int 0/1 alarms).
        if self.statistic is not None:
            self.statistic = np.asarray(self.statistic)
        if self.alarms is not None:
            self.alarms = np.asarray(self.alarms, dtype=bool)
        if self.threshold is not None:
            self.threshold = float(self.threshold)
        self.traces = {str(k): np.asarray(v) for k, v in self.traces.items()}
        if self.estimate_xy is not None:
            self.estimate_xy = np.asarray(self.estimate_xy)

    def check(self, k: int, where: str) -> None:
        """Raise ValueError if an array does not fit ``K = k`` steps."""
        _check_shape(self.statistic, (k,), f"{where}.statistic")
        _check_shape(self.alarms, (k,), f"{where}.alarms")
        _check_shape(self.estimate_xy, (k, 2), f"{where}.estimate_xy")
        for name, arr in self.traces.items():
            _check_shape(arr, (k,), f"{where}.traces[{name!r}]")


@dataclass(eq=False)
class TrialRecord:
    """Everything recorded for one selected trial.

    scenario : registry name, e.g. ``"cv-turn-cv"``.
    snr_db : SNR of the trial's level; ``None`` for a null-hypothesis trial.
    trial : global trial index within its SNR level.
    t : (K,) seconds. truth_xy, measurements_xy : (K, 2) metres (NaN rows
    allowed in measurements: missed detections).
    methods : method config label (e.g. ``"cumulant[window=32]"``) -> trace.
    """

    scenario: str
    snr_db: float | None
    trial: int
    t: np.ndarray
    truth_xy: np.ndarray
    measurements_xy: np.ndarray
    methods: dict[str, MethodTrace] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.scenario = str(self.scenario)
        self.snr_db = None if self.snr_db is None else float(self.snr_db)
        self.trial = int(self.trial)
        self.t = np.asarray(self.t)
        self.truth_xy = np.asarray(self.truth_xy)
        self.measurements_xy = np.asarray(self.measurements_xy)
        self.methods = {str(k): v for k, v in self.methods.items()}
        self._check()

    @property
    def steps(self) -> int:
        return int(self.t.shape[0])

    def _check(self) -> None:
        # Fail in the worker, where the bug is, not later in the driver.
        _check_shape(self.t, (None,), "t")
        k = self.steps
        _check_shape(self.truth_xy, (k, 2), "truth_xy")
        _check_shape(self.measurements_xy, (k, 2), "measurements_xy")
        for label, trace in self.methods.items():
            trace.check(k, f"methods[{label!r}]")

    # -- serialisation -----------------------------------------------------

    def to_bytes(self) -> bytes:
        """Compressed ``.npz`` bytes: arrays plus a JSON header (no pickle)."""
        arrays: dict[str, np.ndarray] = {
            "t": self.t, "truth_xy": self.truth_xy, "measurements_xy": self.measurements_xy,
        }
        methods = []
        for i, (label, tr) in enumerate(self.methods.items()):
            # Labels and trace names live in the header; array keys are
            # positional so that any label is a valid key.
            for key in ("statistic", "alarms", "estimate_xy"):
                if getattr(tr, key) is not None:
                    arrays[f"m{i}_{key}"] = getattr(tr, key)
            for j, arr in enumerate(tr.traces.values()):
                arrays[f"m{i}_trace{j}"] = arr
            methods.append({
                "label": label,
                "threshold": tr.threshold,
                "has": [k for k in ("statistic", "alarms", "estimate_xy") if getattr(tr, k) is not None],
                "traces": list(tr.traces),
            })
        header = {
            "version": _FORMAT_VERSION, "scenario": self.scenario, "snr_db": self.snr_db,
            "trial": self.trial, "methods": methods,
        }
        # JSON floats are written with repr(), so they round-trip exactly
        # (inf/nan included, as Python's json writes them).
        arrays["header"] = np.frombuffer(json.dumps(header).encode("utf-8"), dtype=np.uint8)
        buf = io.BytesIO()
        np.savez_compressed(buf, **arrays)
        return buf.getvalue()

    @classmethod
    def from_bytes(cls, data: bytes) -> "TrialRecord":
        """Inverse of :meth:`to_bytes`."""
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            header = json.loads(z["header"].tobytes().decode("utf-8"))
            if header.get("version") != _FORMAT_VERSION:
                raise ValueError(f"TrialRecord bytes: unsupported version {header.get('version')!r}")
            methods = {m["label"]: _trace_from_npz(z, i, m) for i, m in enumerate(header["methods"])}
            return cls(
                scenario=header["scenario"], snr_db=header["snr_db"], trial=header["trial"],
                t=z["t"], truth_xy=z["truth_xy"], measurements_xy=z["measurements_xy"],
                methods=methods,
            )


def _trace_from_npz(z, i: int, meta: dict) -> MethodTrace:
    """One MethodTrace from the ``m{i}_*`` arrays of a loaded npz."""
    has = set(meta["has"])
    get = lambda key: z[f"m{i}_{key}"] if key in has else None  # noqa: E731
    traces = {name: z[f"m{i}_trace{j}"] for j, name in enumerate(meta["traces"])}
    return MethodTrace(
        statistic=get("statistic"), threshold=meta["threshold"], alarms=get("alarms"),
        traces=traces, estimate_xy=get("estimate_xy"),
    )


def _check_shape(arr: np.ndarray | None, shape: tuple, where: str) -> None:
    """ValueError naming the field when ``arr`` is not numeric of ``shape``."""
    if arr is None:
        return
    if arr.dtype.kind not in "biuf":
        raise ValueError(f"TrialRecord.{where}: expected a numeric array, got dtype {arr.dtype}")
    ok = arr.ndim == len(shape) and all(s is None or s == n for s, n in zip(shape, arr.shape))
    if not ok:
        want = str(tuple("K" if s is None else s for s in shape)).replace("'", "")
        raise ValueError(f"TrialRecord.{where}: expected shape {want}, got {arr.shape}")


# --------------------------------------------------------------------------
# Entity paths
# --------------------------------------------------------------------------

_SEPARATORS = re.compile(r"[\[\](){},;\s]+")
_UNSAFE = re.compile(r"[^A-Za-z0-9_.\-]+")


def entity_name(label: str) -> str:
    """A readable entity-path part for a method config label.

    Rerun leaves only ``A-Z a-z 0-9 _ - .`` unescaped in entity paths; any
    other character is stored backslash-escaped (``[`` -> ``\\[``), which is
    unreadable and error-prone in blueprints and queries. So: ``=`` becomes
    ``-``, brackets, commas and whitespace become ``_`` (runs collapse, ends
    are trimmed), anything else becomes ``-``::

        cumulant[window=32]                  -> cumulant_window-32
        innovation[window=5, variant=fading] -> innovation_window-5_variant-fading

    Not injective in general (``a[b_c=1]`` and ``a_b[c=1]`` meet), so a set of
    labels is named with :func:`method_entity_names`, which disambiguates.
    """
    name = _SEPARATORS.sub("_", str(label).replace("=", "-"))
    name = _UNSAFE.sub("-", name).strip("_")
    # A leading "__" would also be trimmed: rerun reserves it (/__properties).
    return name or "unnamed"


def method_entity_names(labels: Iterable[str], reserved: Iterable[str] = ()) -> dict[str, str]:
    """Injective label -> entity name map for the labels of one parent entity.

    Labels whose :func:`entity_name` collides (with each other or with a
    ``reserved`` sibling name) get a short stable hash of the label appended,
    so the mapping never depends on the order of the labels.
    """
    labels = list(dict.fromkeys(str(x) for x in labels))
    reserved = set(reserved)
    base = {label: entity_name(label) for label in labels}
    counts: dict[str, int] = {}
    for name in base.values():
        counts[name] = counts.get(name, 0) + 1
    out = {}
    for label, name in base.items():
        if counts[name] > 1 or name in reserved:
            name = f"{name}-{hashlib.sha1(label.encode('utf-8')).hexdigest()[:6]}"
        out[label] = name
    return out


def snr_part(snr_db: float | None) -> str:
    """``snr_+05dB`` / ``snr_-05dB`` / ``snr_+02p5dB``; ``null`` for None."""
    if snr_db is None:
        return "null"
    x = round(float(snr_db), 6)
    if not math.isfinite(x):
        raise ValueError(f"snr_db must be finite or None, got {snr_db!r}")
    sign = "-" if x < 0 else "+"  # round() turned -0.0-ish values into 0 -> "+"
    whole, _, frac = f"{abs(x):.6f}".rstrip("0").rstrip(".").partition(".")
    return f"snr_{sign}{int(whole):02d}{'p' + frac if frac else ''}dB"


def entity_root(scenario: str, snr_db: float | None, trial: int) -> str:
    """Readable root entity of one trial, e.g. ``/cv-turn-cv/snr_+05dB/trial_003``."""
    if int(trial) < 0:
        raise ValueError(f"trial must be >= 0, got {trial!r}")
    return f"/{entity_name(scenario)}/{snr_part(snr_db)}/trial_{int(trial):03d}"


def rerun_path(path: str) -> str:
    """Rerun's canonical (escaped) form of a readable path made by this module.

    ``/cv-turn-cv/snr_+05dB/trial_000`` -> ``/cv-turn-cv/snr_\\+05dB/trial_000``.
    This is the form :class:`rerun.chunk.RrdReader` reports, and the one this
    module passes to the SDK (so rerun never has to guess).
    """
    import rerun as rr

    parts = [p for p in path.split("/") if p]
    return "/" + "/".join(rr.escape_entity_path_part(p) for p in parts)


@dataclass(frozen=True)
class _MethodLayout:
    """Readable entity paths of one method under one trial."""

    label: str
    color: tuple[int, int, int]
    base: str
    traces: dict[str, str]  # trace key -> entity path

    def path(self, child: str) -> str:
        return f"{self.base}/{child}"


@dataclass(frozen=True)
class _TrialLayout:
    """Entity paths and a tab title for one record: one source for the
    logging code and the blueprint, so the two cannot disagree."""

    root: str
    scenario: str
    title: str  # without the scenario, which is the same in most recordings
    sort_key: tuple
    has_statistic: bool
    methods: tuple[_MethodLayout, ...]

    @property
    def trace_paths(self) -> list[str]:
        return [p for m in self.methods for p in m.traces.values()]


def _layout(rec: TrialRecord) -> _TrialLayout:
    root = entity_root(rec.scenario, rec.snr_db, rec.trial)
    names = method_entity_names(rec.methods, reserved={"truth", "measurements"})
    methods = []
    # Colours follow the sorted labels, so the same configs get the same
    # colour in every trial of a sweep.
    for i, label in enumerate(sorted(rec.methods)):
        base = f"{root}/{names[label]}"
        tnames = method_entity_names(rec.methods[label].traces, reserved=_RESERVED)
        traces = {key: f"{base}/{tnames[key]}" for key in rec.methods[label].traces}
        methods.append(_MethodLayout(label, _PALETTE[i % len(_PALETTE)], base, traces))
    snr = "null" if rec.snr_db is None else f"{rec.snr_db:+g} dB"
    return _TrialLayout(
        root=root,
        scenario=rec.scenario,
        title=f"{snr} · trial {rec.trial}",
        sort_key=(rec.scenario, rec.snr_db is None, rec.snr_db or 0.0, rec.trial),
        has_statistic=any(m.statistic is not None for m in rec.methods.values()),
        methods=tuple(methods),
    )


# --------------------------------------------------------------------------
# Logging (shared by the file writer and the live viewer)
# --------------------------------------------------------------------------


def _indexes(steps: np.ndarray, t: np.ndarray) -> list:
    """``step`` and ``time`` time columns for the given step indices."""
    import rerun as rr

    return [
        rr.TimeColumn("step", sequence=steps.astype(np.int64)),
        rr.TimeColumn("time", duration=np.asarray(t, dtype=np.float64)[steps]),
    ]


def _north_up(xy: np.ndarray) -> np.ndarray:
    """Negate y: 2D views draw +y downwards, radar plots have north up."""
    return np.column_stack([xy[:, 0], -xy[:, 1]]).astype(np.float32)


def _log_series(stream, path: str, t: np.ndarray, steps: np.ndarray, values: np.ndarray, style) -> None:
    """Static styling plus one ``send_columns`` for a scalar series."""
    import rerun as rr

    if steps.size == 0:
        return  # empty chunks crash the 0.41 viewer
    path = rerun_path(path)
    stream.log(path, style, static=True)
    stream.send_columns(
        path, indexes=_indexes(steps, t),
        columns=rr.Scalars.columns(scalars=np.asarray(values, dtype=np.float64)),
    )


def _log_points(stream, path: str, t: np.ndarray, xy: np.ndarray, color, radius: float) -> np.ndarray:
    """One Points2D per step with finite coordinates; returns those steps."""
    import rerun as rr

    steps = np.flatnonzero(np.isfinite(xy).all(axis=1))
    if steps.size == 0:
        return steps
    path = rerun_path(path)
    ui = rr.components.Radius.ui_points(radius)
    stream.log(path, rr.Points2D.from_fields(colors=[color], radii=[ui]), static=True)
    stream.send_columns(
        path, indexes=_indexes(steps, t),
        columns=rr.Points2D.columns(positions=_north_up(xy[steps])),
    )
    return steps


def _log_track(stream, path: str, t: np.ndarray, xy: np.ndarray, color) -> None:
    """Current position per step plus the whole track as a static line."""
    import rerun as rr

    steps = _log_points(stream, path, t, xy, color, radius=5.0)
    if steps.size:
        stream.log(
            rerun_path(path),
            rr.LineStrips2D([_north_up(xy[steps])], colors=[color],
                            radii=[rr.components.Radius.ui_points(1.0)]),
            static=True,
        )


def _log_measurements(stream, root: str, t: np.ndarray, xy: np.ndarray) -> None:
    """Current measurement per step, and all of them as a static cloud."""
    import rerun as rr

    steps = _log_points(stream, f"{root}/measurements", t, xy, _MEASUREMENT_COLOR, radius=4.0)
    if steps.size:
        # A child entity: static positions on `measurements` itself would
        # shadow the per-step ones.
        dim = (*_MEASUREMENT_COLOR, 110)
        stream.log(
            rerun_path(f"{root}/measurements/all"),
            rr.Points2D(_north_up(xy[steps]), colors=[dim],
                        radii=[rr.components.Radius.ui_points(2.0)]),
            static=True,
        )


def _log_method(stream, m: _MethodLayout, tr: MethodTrace, t: np.ndarray) -> None:
    """Statistic, threshold, alarms, traces and estimate of one method."""
    import rerun as rr

    k = t.shape[0]
    every = np.arange(k)
    if tr.statistic is not None:
        _log_series(stream, m.path("statistic"), t, every, tr.statistic,
                    rr.SeriesLines(names=m.label, colors=[m.color], widths=[1.5]))
        if tr.threshold is not None and math.isfinite(tr.threshold):
            # Lighter and thinner than the statistic: a reference line.
            _log_series(stream, m.path("threshold"), t, every, np.full(k, tr.threshold),
                        rr.SeriesLines(names=f"{m.label} threshold", colors=[(*m.color, 150)],
                                       widths=[1.0]))
        if tr.alarms is not None:
            hits = np.flatnonzero(tr.alarms)
            _log_series(stream, m.path("alarms"), t, hits, tr.statistic[hits],
                        rr.SeriesPoints(names=f"{m.label} alarms", colors=[m.color],
                                        markers=["cross"], marker_sizes=[5.0]))
    for key, path in m.traces.items():
        _log_series(stream, path, t, every, tr.traces[key],
                    rr.SeriesLines(names=f"{m.label} {key}", colors=[m.color], widths=[1.0]))
    if tr.estimate_xy is not None:
        _log_track(stream, m.path("estimate"), t, tr.estimate_xy, m.color)


def _log_record(rec: TrialRecord, stream, layout: _TrialLayout | None = None) -> _TrialLayout:
    """Log one trial into ``stream``; returns its layout (for the blueprint)."""
    layout = layout or _layout(rec)
    t = np.asarray(rec.t, dtype=np.float64)
    _log_track(stream, f"{layout.root}/truth", t, rec.truth_xy, _TRUTH_COLOR)
    _log_measurements(stream, layout.root, t, rec.measurements_xy)
    for m in layout.methods:
        _log_method(stream, m, rec.methods[m.label], t)
    return layout


def _log_records(records: Iterable[TrialRecord], stream) -> list[_TrialLayout]:
    """Log records, flushing every FLUSH_EVERY to keep the sink queue short."""
    layouts = []
    for i, rec in enumerate(records, start=1):
        layouts.append(_log_record(rec, stream))
        if i % FLUSH_EVERY == 0:
            stream.flush()
    return layouts


# --------------------------------------------------------------------------
# Summary (static, so it shows on any timeline)
# --------------------------------------------------------------------------

_TABLE_COLUMNS = [
    "scenario", "method", "snr_db", "n_trials", "pd", "pd_low", "pd_high",
    "pfa", "pfa_low", "pfa_high", "delay_mean", "rmse_mean",
]


def _pd_curves(summary: "pd.DataFrame") -> list[tuple[str, tuple, "pd.DataFrame"]]:
    """(entity path, colour, rows sorted by SNR) per curve with data.

    One curve per method, or per (scenario, method) when the summary mixes
    scenarios. Colours follow the sorted labels, as in the trial plots.
    """
    df = summary.dropna(subset=["snr_db", "pd"])
    multi = "scenario" in df.columns and df["scenario"].nunique() > 1
    groups = list(df.groupby(["scenario", "method"] if multi else ["method"], sort=False))
    labels = sorted({str(key[-1]) for key, _ in groups})  # keys are tuples (list `by`)
    names = method_entity_names(labels)
    out = []
    for key, rows in groups:
        label = str(key[-1])
        scope = f"{entity_name(str(key[0]))}/" if multi else ""
        color = _PALETTE[labels.index(label) % len(_PALETTE)]
        out.append((f"/summary/pd_vs_snr/{scope}{names[label]}", color, rows.sort_values("snr_db")))
    return out


def _log_pd_bars(stream, summary: "pd.DataFrame") -> None:
    """Grouped bars: one BarChart per curve, shifted so bars sit side by side.

    A BarChart is static and needs no timeline; its legend entry is the entity
    name (BarChart has no series name).
    """
    import rerun as rr

    curves = _pd_curves(summary)
    if not curves:
        return
    snrs = np.unique(np.concatenate([rows["snr_db"].to_numpy(float) for _, _, rows in curves]))
    step = float(np.min(np.diff(snrs))) if snrs.size > 1 else 1.0
    width = 0.8 * step / len(curves)
    for i, (path, color, rows) in enumerate(curves):
        x = rows["snr_db"].to_numpy(float) + (i - (len(curves) - 1) / 2) * width
        stream.log(
            rerun_path(path),
            rr.BarChart(rows["pd"].to_numpy(float), abscissa=x,
                        widths=np.full(x.size, width, np.float32), color=color),
            static=True,
        )


def _cell(v) -> str:
    """Markdown cell: floats to 3 significant digits, blanks for NaN/None."""
    import pandas as pd

    if pd.api.types.is_scalar(v) and pd.isna(v):
        return ""
    if isinstance(v, (float, np.floating)):
        return f"{float(v):.3g}"
    return str(v).replace("|", "\\|")


def _markdown_table(df: "pd.DataFrame") -> str:
    cols = [str(c) for c in df.columns]
    lines = ["| " + " | ".join(_cell(c) for c in cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(_cell(v) for v in row) + " |" for row in df.itertuples(index=False)]
    return "\n".join(lines)


def _summary_markdown(summary: "pd.DataFrame") -> str:
    """A compact Pd pivot (SNR x method) then the key columns of every row."""
    parts = ["# Summary"]
    df = summary.dropna(subset=["snr_db", "pd"])
    if not df.empty and ("scenario" not in df.columns or df["scenario"].nunique() <= 1):
        pivot = df.pivot_table(index="snr_db", columns="method", values="pd", sort=False)
        pivot = pivot.sort_index().reset_index()
        parts += ["## Pd by SNR (dB)", _markdown_table(pivot)]
    cols = [c for c in _TABLE_COLUMNS if c in summary.columns]
    parts += ["## All rows", _markdown_table(summary[cols])]
    return "\n\n".join(parts) + "\n"


def _has_summary(summary: "pd.DataFrame | None") -> bool:
    """False for no/empty summary; ValueError when a needed column is missing."""
    if summary is None or summary.empty:
        return False
    missing = {"method", "snr_db", "pd"} - set(summary.columns)
    if missing:
        raise ValueError(f"summary: missing column(s) {', '.join(sorted(missing))}")
    return True


def _log_summary(stream, summary: "pd.DataFrame | None") -> bool:
    """Pd-vs-SNR bars and a Markdown table; False when there is nothing."""
    import rerun as rr

    if not _has_summary(summary):
        return False
    _log_pd_bars(stream, summary)
    stream.log("/summary/table", rr.TextDocument(_summary_markdown(summary),
                                                 media_type=rr.MediaType.MARKDOWN), static=True)
    return True


# --------------------------------------------------------------------------
# Default blueprint
# --------------------------------------------------------------------------


def _trial_tab(layout: _TrialLayout, title: str):
    """Statistics over time on top; the 2D track (and traces) below."""
    import rerun.blueprint as rrb

    origin = rerun_path(layout.root)
    # Explicit paths: entity filters only support a trailing /**, and
    # $origin spares us re-escaping the root.
    rel = lambda p: "+ $origin" + rerun_path(p)[len(origin):]  # noqa: E731
    stats = [rel(m.path(c)) for m in layout.methods for c in ("statistic", "threshold", "alarms")]
    bottom = [rrb.Spatial2DView(origin=origin, name="track (north up)")]
    if layout.trace_paths:
        bottom.append(rrb.TimeSeriesView(origin=origin, name="traces",
                                         contents=[rel(p) for p in layout.trace_paths]))
    views = [rrb.Horizontal(*bottom) if len(bottom) > 1 else bottom[0]]
    if layout.has_statistic:
        views.insert(0, rrb.TimeSeriesView(origin=origin, name="statistics", contents=stats))
    return rrb.Vertical(*views, name=title)


def _summary_tab():
    import rerun.blueprint as rrb

    return rrb.Horizontal(
        rrb.BarChartView(origin="/summary/pd_vs_snr", name="Pd vs SNR (dB)"),
        rrb.TextDocumentView(origin="/summary/table", name="summary"),
        column_shares=[3, 2], name="summary",
    )


def _blueprint(layouts: list[_TrialLayout], with_summary: bool):
    """Tabs: the first MAX_TABS trials (by scenario, SNR, trial), then the summary."""
    import rerun.blueprint as rrb

    chosen = sorted(layouts, key=lambda lay: lay.sort_key)[:MAX_TABS]
    several = len({lay.scenario for lay in layouts}) > 1
    tabs = [_trial_tab(lay, f"{lay.scenario} {lay.title}" if several else lay.title) for lay in chosen]
    if with_summary:
        tabs.append(_summary_tab())
    parts = [rrb.TimePanel(timeline="step")]
    if tabs:
        parts.insert(0, rrb.Tabs(*tabs, active_tab=0))
    return rrb.Blueprint(*parts)


# --------------------------------------------------------------------------
# Public entry points
# --------------------------------------------------------------------------


def write_recording(
    path: str | os.PathLike,
    records: list[TrialRecord],
    summary: "pd.DataFrame | None" = None,
    *,
    recording_id: str,
    application_id: str = "radar-bench",
) -> Path:
    """Write ``records`` (and the ``summary`` curves) to an ``.rrd`` file.

    Atomic: the file is written to ``path.with_suffix(".rrd.tmp")`` and renamed
    only once complete (footer written), so a crash never leaves a truncated
    ``recording.rrd``. ``summary`` needs columns ``method``, ``snr_db``,
    ``pd``. Returns ``path``.
    """
    import rerun as rr

    path = Path(path)
    tmp = path.with_suffix(".rrd.tmp")
    tmp.parent.mkdir(parents=True, exist_ok=True)
    records = list(records)  # iterated twice: blueprint, then logging
    layouts = [_layout(r) for r in records]  # fails on bad names before any I/O
    has_summary = _has_summary(summary)
    stream = rr.RecordingStream(application_id, recording_id=recording_id)
    try:
        # The sink (and its blueprint) must be attached before logging.
        stream.save(tmp, default_blueprint=_blueprint(layouts, has_summary))
        try:
            _log_records(records, stream)
            _log_summary(stream, summary)
            stream.flush()
        finally:
            stream.disconnect()  # writes the footer
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def _has_display() -> bool:
    """False on Linux/BSD without X11 or Wayland: the viewer cannot open."""
    if sys.platform.startswith(("win", "darwin")):
        return True
    return any(os.environ.get(v) for v in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"))


def _viewer_executable() -> str | None:
    """The ``rerun`` binary: on PATH, or next to this interpreter (venv not activated)."""
    found = shutil.which("rerun")
    if found:
        return found
    local = Path(sys.executable).with_name("rerun.exe" if os.name == "nt" else "rerun")
    return str(local) if local.exists() else None


def _port_open(port: int) -> bool:
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=1.0):
            return True
    except OSError:
        return False


class LiveViewer:
    """Stream records to a spawned Rerun viewer (``bench run --viewer``).

    Uses the same logging code as :func:`write_recording`. The default
    blueprint is re-sent while the set of trial tabs grows (up to MAX_TABS),
    which resets a layout the user changed in the meantime.

    Raises RuntimeError (one line) when no viewer can be started: no display,
    no ``rerun`` executable, or a viewer that never listens on ``port``.
    Spawning reuses a viewer already listening on ``port``.
    """

    def __init__(self, *, recording_id: str, application_id: str = "radar-bench", port: int = 9876):
        import rerun as rr

        if not _has_display():
            raise RuntimeError("cannot open the Rerun viewer: no display (DISPLAY/WAYLAND_DISPLAY unset)")
        exe = _viewer_executable()
        if exe is None:
            raise RuntimeError("cannot open the Rerun viewer: `rerun` executable not found")
        stream = rr.RecordingStream(application_id, recording_id=recording_id)
        try:
            rr.spawn(port=port, connect=True, recording=stream, executable_path=exe,
                     hide_welcome_screen=True)
        except Exception as exc:  # the bindings raise various types
            stream.disconnect()
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else repr(exc)
            raise RuntimeError(f"cannot open the Rerun viewer: {first}") from exc
        # rr.spawn only warns when the viewer dies at start-up: check for real.
        if not _port_open(port):
            stream.disconnect()
            raise RuntimeError(f"cannot open the Rerun viewer: nothing listens on port {port}")
        self._attach(stream)

    @classmethod
    def from_stream(cls, stream) -> "LiveViewer":
        """Wrap a stream whose sink is already set (an existing viewer via
        ``connect_grpc``, a file in tests) instead of spawning a viewer."""
        self = cls.__new__(cls)
        self._attach(stream)
        return self

    def _attach(self, stream) -> None:
        self._stream = stream
        self._layouts: list[_TrialLayout] = []
        self._summary = False
        self._shown: tuple | None = None

    def log_records(self, records: Iterable[TrialRecord]) -> None:
        """Log records now (the viewer shows them as they arrive)."""
        self._layouts += _log_records(records, self._stream)
        self._send_blueprint()

    def log_summary(self, summary: "pd.DataFrame | None") -> None:
        """Log the Pd-vs-SNR curves and table, and add the summary tab."""
        self._summary = _log_summary(self._stream, summary) or self._summary
        self._send_blueprint()

    def _send_blueprint(self) -> None:
        # Only when the tabs change: each send replaces the viewer's layout.
        chosen = tuple(lay.root for lay in sorted(self._layouts, key=lambda x: x.sort_key)[:MAX_TABS])
        if (chosen, self._summary) != self._shown:
            self._stream.send_blueprint(_blueprint(self._layouts, self._summary))
            self._shown = (chosen, self._summary)

    def close(self) -> None:
        """Flush and disconnect; safe to call twice."""
        if self._stream is not None:
            # Bounded: a viewer the user already closed must not hang the run.
            self._stream.flush(timeout_sec=30.0)
            self._stream.disconnect()
            self._stream = None

    def __enter__(self) -> "LiveViewer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
