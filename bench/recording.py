"""Rerun recordings of selected trials.

Workers build one :class:`TrialRecord` per selected trial (``[record] trials``
per SNR); it travels to the driver as bytes (:meth:`TrialRecord.to_bytes`, also
what the SQLite store keeps) and the driver alone writes the recording, either
to a file (:func:`write_recording`) or to a spawned viewer
(:class:`LiveViewer`). Both go through the same ``_log_record``.

One record type serves the three tasks; every task-specific field is optional:

* maneuver detection: ``truth_xy``, ``measurements_xy``, per method
  ``statistic`` / ``threshold`` / ``alarms`` / ``traces``;
* tracking: ``truth_xy``, ``measurements_xy``, ``measurement_flags`` (glint
  outliers), per method ``estimate_xy`` and error ``traces`` (``error_x``...);
* track-before-detect (TBD): ``frames`` + ``grid`` + ``truth_cells``, per method
  ``track_cells`` / ``value`` / ``score`` / ``threshold`` (``truth_xy`` too when
  known).

Entity paths (readable form; ``{method}`` is :func:`entity_name` of the method
config label, made unique by :func:`method_entity_names`)::

    /{scenario}/snr_{±NN}dB/trial_{NNN}/truth               Points2D per step + static LineStrips2D (whole track)
    .../measurements                                          Points2D per step (missing rows skipped)
    .../measurements/all                                      static Points2D of every measurement
    .../measurements/glint                                    static Points2D of the flagged (glint) measurements, red
    .../frames                                                DepthImage per step (TBD frames, uint8 codes, viridis)
    .../frames/truth_track                                    true cells: Points2D per step + static LineStrips2D, pixel coords
    .../frames/{method}_track                                 backtracked cells of a TBD method, same form
    .../{method}/statistic                                    Scalars
    .../{method}/threshold                                    Scalars, the threshold in force at every step
    .../{method}/alarms                                       Scalars at alarm steps only (the statistic there), drawn as points
    .../{method}/score                                        Scalars: the scene score of a TBD method, a flat line over the steps
    .../{method}/value                                        static DepthImage: merit map at the last frame (uint8 codes, inferno)
    .../{method}/{trace}                                      Scalars (extra series: whitened innovation, error_x, ...)
    .../{method}/estimate                                     like truth (trackers)
    /summary/pd_vs_snr/{method}                               static BarChart of Pd (abscissa = SNR, dB)
    /summary/rmse_vs_snr/{method}                             static BarChart of rmse_mean (m), when the summary has it
    /summary/table                                            static TextDocument (Markdown)

When the summary mixes scenarios, the bar charts gain a level:
``/summary/pd_vs_snr/{scenario}/{method}``. A score or threshold that is
``None`` or non-finite is not drawn, nor is a threshold with no finite
statistic or score to compare with; cells outside the grid (e.g. ``-1``) are
left out of the track strips.

SNR parts: ``snr_+05dB``, ``snr_-05dB``, ``snr_+02p5dB`` (non-integer SNR; ``p``
stands for the decimal point), ``null`` for null-hypothesis trials. Rerun keeps
paths in an escaped canonical form in which ``+`` becomes ``\\+``
(``/cv-turn-cv/snr_\\+05dB/trial_000``); the viewer shows the readable form.
:func:`rerun_path` converts a readable path to the canonical one, which is
what :class:`rerun.chunk.RrdReader` returns.

Timelines: every time series carries ``step`` (sequence, 0..K-1) and ``time``
(duration, seconds, from ``t``); so do the TBD frames. Summary data, value maps
and whole-track lines are static, so they show whatever timeline is selected.

Orientation: Rerun's 2D views draw +y downwards. Positions are logged with
**y negated** so that north (+y) is up on screen; x is unchanged. Anyone
reading positions back from the file must negate y again. TBD images follow
the same rule: grid row ``r`` (``y = y_min + (r + 0.5)·cell_m``) is drawn at
image row ``rows - 1 - r``, so north is up; a cell ``(row, col)`` is drawn at
pixel coordinates ``(col + 0.5, rows - row - 0.5)`` (its centre), which is
where the track strips under ``.../frames`` are logged.

Quantisation (TBD ``frames`` and ``value`` maps, see :class:`Quantised`): each
array gets its own range ``[lo, hi]`` with ``lo = max(min, mean - 3·std)`` and
``hi = min(max, mean + 6·std)`` over its finite values (a whole trial's frames
share one range; each value map has its own). Values are clipped to the range
and mapped linearly to codes 1..255 (``value = lo + (code - 1)·(hi - lo)/254``,
error ≤ (hi - lo)/508, about 0.02 std); code 0 marks a non-finite value. A
target brighter than mean + 6·std saturates at code 255. The bytes keep the
codes plus ``lo``/``hi``; the recording logs the codes (``depth_range`` 1..255,
``meter`` 1, so the viewer's hover shows the code) with static ``AnyValues`` on
the same entity: ``code_lo``, ``code_hi``, a ``codes`` note, ``orientation`` and,
for frames, ``grid_rows`` ... ``grid_y_min_m``. A 500×500×20 trial is 5 MB of
codes (4.5-5 MB compressed for noise), instead of 20 MB float32.

Whole series are sent with ``send_columns`` (one call per entity, not one
``log`` per sample: ~500x faster), TBD frames too (one column of K images),
and a zero-length column is never sent (the 0.41 viewer panics on empty chunks).
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
from typing import TYPE_CHECKING, Self

import numpy as np

# rerun (and pandas) are imported inside the functions that need them: workers
# import this module only for TrialRecord, and `import rerun` costs ~0.5 s.
if TYPE_CHECKING:  # pragma: no cover - typing only
    import pandas as pd

__all__ = [
    "GRID_KEYS",
    "MAX_TABS",
    "LiveViewer",
    "MethodTrace",
    "Quantised",
    "TrialRecord",
    "entity_name",
    "entity_root",
    "method_entity_names",
    "rerun_path",
    "snr_part",
    "write_recording",
]

#: Trials that get their own tab in the default blueprint; more tabs are unusable.
MAX_TABS = 12
#: Records logged between two flushes: the file sink queue is unbounded.
FLUSH_EVERY = 50
#: Bumped when the byte layout of :meth:`TrialRecord.to_bytes` changes.
#: 2: optional truth/measurements, TBD frames/grid/cells, glint flags, track
#: cells/value/score. Version 1 bytes still load (a subset of version 2).
_FORMAT_VERSION = 2
_READABLE_VERSIONS = frozenset({1, 2})
#: Children of a method entity that traces must not shadow.
_RESERVED = frozenset({"statistic", "threshold", "alarms", "estimate", "score", "value"})
#: Children of a trial root that method entities must not shadow.
_ROOT_CHILDREN = frozenset({"truth", "measurements", "frames"})
#: Keys of :attr:`TrialRecord.grid`.
GRID_KEYS = ("rows", "cols", "cell_m", "x_min_m", "y_min_m")
#: Quantisation range, in standard deviations below / above the mean.
QUANT_SIGMAS = (3.0, 6.0)
#: Trace views per tab: up to this many distinct trace names get one view each
#: (a tracker's error_x ... error_vz), more share one view.
_MAX_TRACE_VIEWS = 8

# tab10: distinct on the viewer's dark background.
_PALETTE = [
    (31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
    (140, 86, 75), (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207),
]
_TRUTH_COLOR = (230, 230, 230)
_MEASUREMENT_COLOR = (255, 200, 60)
_GLINT_COLOR = (255, 40, 90)
_FRAMES_COLORMAP = "viridis"
_VALUE_COLORMAP = "inferno"


# --------------------------------------------------------------------------
# Quantised arrays (TBD frames and value maps)
# --------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Quantised:
    """An array held as uint8 codes: 0 = non-finite, 1..255 linear on [lo, hi].

    Build with :meth:`of`; :meth:`values` gives float32 back (NaN at code 0).
    """

    codes: np.ndarray
    lo: float
    hi: float

    @classmethod
    def of(cls, x) -> Quantised:
        """Codes of ``x`` on ``[max(min, mean-3σ), min(max, mean+6σ)]`` (finite values)."""
        x = np.asarray(x)
        if x.dtype.kind not in "biuf":
            raise ValueError(f"cannot quantise dtype {x.dtype}")
        x = x.astype(np.float32, copy=False) if x.dtype.kind == "f" else x.astype(np.float64)
        finite = np.isfinite(x)
        all_finite = bool(finite.all())
        v = x if all_finite else x[finite]
        if v.size == 0:
            return cls(np.zeros(x.shape, np.uint8), 0.0, 0.0)
        mean, std = float(v.mean(dtype=np.float64)), float(v.std(dtype=np.float64))
        lo = max(float(v.min()), mean - QUANT_SIGMAS[0] * std)
        hi = min(float(v.max()), mean + QUANT_SIGMAS[1] * std)
        hi = max(hi, lo)  # rounding of mean/std on a constant array
        scale = 254.0 / (hi - lo) if hi > lo else 0.0
        codes = np.rint((np.clip(x, lo, hi) - lo) * scale)
        codes += 1.0
        if not all_finite:
            codes[~finite] = 0.0
        return cls(codes.astype(np.uint8), lo, hi)

    def values(self) -> np.ndarray:
        """Float32 values at the code centres; NaN where the code is 0."""
        step = (self.hi - self.lo) / 254.0
        out = self.codes.astype(np.float32)
        out -= 1.0
        out *= np.float32(step)
        out += np.float32(self.lo)
        out[self.codes == 0] = np.nan
        return out

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(self.codes.shape)


class _QuantisableArray:
    """Dataclass field descriptor for a float array that may be held quantised.

    Set it to an array (kept as given) or to a :class:`Quantised` (what
    :meth:`TrialRecord.from_bytes` does: codes only, 4x less memory than
    float32); reading a quantised one dequantises it on every access.
    """

    def __set_name__(self, owner, name: str) -> None:
        self._slot = f"_{name}_held"

    def __get__(self, obj, owner=None):
        if obj is None:
            return None  # the dataclass default
        held = obj.__dict__.get(self._slot)
        return held.values() if isinstance(held, Quantised) else held

    def __set__(self, obj, value) -> None:
        if value is not None and not isinstance(value, Quantised):
            value = np.asarray(value)
        obj.__dict__[self._slot] = value


def _held(obj, name: str):
    """The stored form (array, Quantised or None) of a quantisable field."""
    return obj.__dict__.get(f"_{name}_held")


def _quantised(obj, name: str) -> Quantised | None:
    held = _held(obj, name)
    if held is None or isinstance(held, Quantised):
        return held
    return Quantised.of(held)


def _held_array(obj, name: str) -> np.ndarray | None:
    """An array of the stored shape, for checks (codes when quantised)."""
    held = _held(obj, name)
    return held.codes if isinstance(held, Quantised) else held


# --------------------------------------------------------------------------
# Data carried from workers to the driver
# --------------------------------------------------------------------------

_METHOD_ARRAYS = ("statistic", "alarms", "estimate_xy", "track_cells")


@dataclass(eq=False)
class MethodTrace:
    """What one method config produced on one recorded trial.

    statistic : (K,) float — detector statistic (``None`` for trackers, TBD).
    threshold : float — the threshold in force (nominal or calibrated; for TBD
        the scene threshold on ``score``); ``None`` or non-finite: not drawn.
    alarms : (K,) bool — ``statistic >= threshold`` as the harness decided it.
    traces : name -> (K,) float — extra series (e.g. whitened innovation, or a
        tracker's ``error_x`` / ``error_y`` / ``error_pos`` in metres).
    estimate_xy : (K, 2) float or None — position estimate, metres (trackers).
    track_cells : (K, 2) int or None — TBD backtracked track, ``(row, col)``
        per frame; cells outside the grid (e.g. -1) are not drawn, and the
        track is drawn only when the record has frames or a grid.
    value : (H, W) float or None — TBD merit map at the last frame. Quantised in
        the bytes (own range); after :meth:`TrialRecord.from_bytes` reading it
        gives float32 dequantised values.
    score : float or None — TBD scene score (NaN allowed, not drawn).
    """

    statistic: np.ndarray | None
    threshold: float | None
    alarms: np.ndarray | None
    traces: dict[str, np.ndarray] = field(default_factory=dict)
    estimate_xy: np.ndarray | None = None
    track_cells: np.ndarray | None = None
    value: np.ndarray | None = _QuantisableArray()
    score: float | None = None

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
        self.track_cells = _cells(self.track_cells)
        if self.score is not None:
            self.score = float(self.score)

    def check(self, k: int, where: str, image: tuple[int, int] | None = None) -> None:
        """Raise ValueError if an array does not fit ``K = k`` steps (and,
        when given, ``image = (H, W)`` for the value map)."""
        _check_shape(self.statistic, (k,), f"{where}.statistic")
        _check_shape(self.alarms, (k,), f"{where}.alarms")
        _check_shape(self.estimate_xy, (k, 2), f"{where}.estimate_xy")
        _check_shape(self.track_cells, (k, 2), f"{where}.track_cells", kinds="iu")
        _check_shape(_held_array(self, "value"), image or (None, None), f"{where}.value")
        for name, arr in self.traces.items():
            _check_shape(arr, (k,), f"{where}.traces[{name!r}]")


def _cells(arr) -> np.ndarray | None:
    """Integer cells as int32 (other dtypes are left for the check to reject)."""
    if arr is None:
        return None
    arr = np.asarray(arr)
    return arr.astype(np.int32) if arr.dtype.kind in "iu" else arr


@dataclass(eq=False)
class TrialRecord:
    """Everything recorded for one selected trial.

    scenario : registry name or config label, e.g. ``"cv-turn-cv"``.
    snr_db : SNR of the trial's level; ``None`` for a null-hypothesis trial.
    trial : global trial index within its SNR level.
    t : (K,) seconds.
    truth_xy, measurements_xy : (K, 2) metres or None (NaN rows allowed: not
        drawn, e.g. missed detections).
    methods : method config label (e.g. ``"cumulant[window=32]"``) -> trace.
    frames : (K, H, W) float or None — TBD frames. Quantised to uint8 in the
        bytes (see the module docstring); after :meth:`from_bytes` reading it
        gives float32 dequantised values (computed on each access).
    grid : dict or None — ``rows``, ``cols`` (int), ``cell_m``, ``x_min_m``,
        ``y_min_m`` (float); cell ``(row, col)`` centre is
        ``x = x_min + (col + 0.5)·cell_m``, ``y = y_min + (row + 0.5)·cell_m``.
        Must match ``frames`` when both are given.
    truth_cells : (K, 2) int or None — true target cell ``(row, col)`` per
        frame (None under the null); stored as int32.
    measurement_flags : (K,) bool or None — steps whose measurement had a
        glint outlier (drawn under ``.../measurements/glint``).
    """

    scenario: str
    snr_db: float | None
    trial: int
    t: np.ndarray
    truth_xy: np.ndarray | None = None
    measurements_xy: np.ndarray | None = None
    methods: dict[str, MethodTrace] = field(default_factory=dict)
    frames: np.ndarray | None = _QuantisableArray()
    grid: dict | None = None
    truth_cells: np.ndarray | None = None
    measurement_flags: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.scenario = str(self.scenario)
        self.snr_db = None if self.snr_db is None else float(self.snr_db)
        self.trial = int(self.trial)
        self.t = np.asarray(self.t)
        if self.truth_xy is not None:
            self.truth_xy = np.asarray(self.truth_xy)
        if self.measurements_xy is not None:
            self.measurements_xy = np.asarray(self.measurements_xy)
        self.methods = {str(k): v for k, v in self.methods.items()}
        self.grid = _grid(self.grid)
        self.truth_cells = _cells(self.truth_cells)
        if self.measurement_flags is not None:
            self.measurement_flags = np.asarray(self.measurement_flags, dtype=bool)
        self._check()

    @property
    def steps(self) -> int:
        return int(self.t.shape[0])

    @property
    def image_shape(self) -> tuple[int, int] | None:
        """(H, W) of the TBD images: from frames, else the grid, else None."""
        frames = _held_array(self, "frames")
        if frames is not None and frames.ndim == 3:
            return int(frames.shape[1]), int(frames.shape[2])
        if self.grid is not None:
            return self.grid["rows"], self.grid["cols"]
        return None

    def _check(self) -> None:
        # Fail in the worker, where the bug is, not later in the driver.
        _check_shape(self.t, (None,), "t")
        k = self.steps
        _check_shape(self.truth_xy, (k, 2), "truth_xy")
        _check_shape(self.measurements_xy, (k, 2), "measurements_xy")
        frames = _held_array(self, "frames")
        _check_shape(frames, (k, None, None), "frames")
        grid_shape = None if self.grid is None else (self.grid["rows"], self.grid["cols"])
        if frames is not None and grid_shape is not None and frames.shape[1:] != grid_shape:
            raise ValueError(f"TrialRecord.grid: rows x cols = {grid_shape[0]} x {grid_shape[1]} "
                             f"does not match frames {frames.shape[1]} x {frames.shape[2]}")
        _check_shape(self.truth_cells, (k, 2), "truth_cells", kinds="iu")
        _check_shape(self.measurement_flags, (k,), "measurement_flags")
        image = self.image_shape
        for label, trace in self.methods.items():
            trace.check(k, f"methods[{label!r}]", image)

    # -- serialisation -----------------------------------------------------

    def to_bytes(self) -> bytes:
        """Compressed ``.npz`` bytes: arrays plus a JSON header (no pickle).

        TBD frames and value maps are stored as uint8 codes plus their range
        (:class:`Quantised`); everything else is exact.
        """
        arrays: dict[str, np.ndarray] = {"t": self.t}
        header: dict = {
            "version": _FORMAT_VERSION, "scenario": self.scenario, "snr_db": self.snr_db,
            "trial": self.trial, "has": [], "grid": self.grid,
        }
        for key in ("truth_xy", "measurements_xy", "truth_cells", "measurement_flags"):
            if getattr(self, key) is not None:
                arrays[key] = getattr(self, key)
                header["has"].append(key)
        q = _quantised(self, "frames")
        if q is not None:
            arrays["frames"] = q.codes
            header["frames_range"] = [q.lo, q.hi]
        methods = []
        for i, (label, tr) in enumerate(self.methods.items()):
            # Labels and trace names live in the header; array keys are
            # positional so that any label is a valid key.
            has = [k for k in _METHOD_ARRAYS if getattr(tr, k) is not None]
            for key in has:
                arrays[f"m{i}_{key}"] = getattr(tr, key)
            for j, arr in enumerate(tr.traces.values()):
                arrays[f"m{i}_trace{j}"] = arr
            meta = {"label": label, "threshold": tr.threshold, "score": tr.score, "has": has,
                    "traces": list(tr.traces)}
            qv = _quantised(tr, "value")
            if qv is not None:
                arrays[f"m{i}_value"] = qv.codes
                meta["value_range"] = [qv.lo, qv.hi]
            methods.append(meta)
        header["methods"] = methods
        # JSON floats are written with repr(), so they round-trip exactly
        # (inf/nan included, as Python's json writes them).
        arrays["header"] = np.frombuffer(json.dumps(header).encode("utf-8"), dtype=np.uint8)
        buf = io.BytesIO()
        np.savez_compressed(buf, **arrays)
        return buf.getvalue()

    @classmethod
    def from_bytes(cls, data: bytes) -> TrialRecord:
        """Inverse of :meth:`to_bytes` (reads format versions 1 and 2)."""
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            header = json.loads(z["header"].tobytes().decode("utf-8"))
            if header.get("version") not in _READABLE_VERSIONS:
                raise ValueError(f"TrialRecord bytes: unsupported version {header.get('version')!r}")
            has = set(header.get("has", ("truth_xy", "measurements_xy")))  # version 1: always both
            get = lambda key: z[key] if key in has else None
            methods = {m["label"]: _trace_from_npz(z, i, m) for i, m in enumerate(header["methods"])}
            frames = None
            if "frames_range" in header:
                frames = Quantised(z["frames"], *map(float, header["frames_range"]))
            return cls(
                scenario=header["scenario"], snr_db=header["snr_db"], trial=header["trial"],
                t=z["t"], truth_xy=get("truth_xy"), measurements_xy=get("measurements_xy"),
                methods=methods, frames=frames, grid=header.get("grid"),
                truth_cells=get("truth_cells"), measurement_flags=get("measurement_flags"),
            )


def _trace_from_npz(z, i: int, meta: dict) -> MethodTrace:
    """One MethodTrace from the ``m{i}_*`` arrays of a loaded npz."""
    has = set(meta["has"])
    get = lambda key: z[f"m{i}_{key}"] if key in has else None
    traces = {name: z[f"m{i}_trace{j}"] for j, name in enumerate(meta["traces"])}
    value = None
    if "value_range" in meta:
        value = Quantised(z[f"m{i}_value"], *map(float, meta["value_range"]))
    return MethodTrace(
        statistic=get("statistic"), threshold=meta["threshold"], alarms=get("alarms"),
        traces=traces, estimate_xy=get("estimate_xy"), track_cells=get("track_cells"),
        value=value, score=meta.get("score"),
    )


def _grid(grid) -> dict | None:
    """The grid dict with exactly GRID_KEYS, ints and floats; ValueError if not."""
    if grid is None:
        return None
    missing = [k for k in GRID_KEYS if k not in grid]
    if missing:
        raise ValueError(f"TrialRecord.grid: missing key(s) {', '.join(missing)}")
    out = {"rows": int(grid["rows"]), "cols": int(grid["cols"])}
    out.update({k: float(grid[k]) for k in GRID_KEYS[2:]})
    if out["rows"] <= 0 or out["cols"] <= 0 or not out["cell_m"] > 0:
        raise ValueError(f"TrialRecord.grid: rows, cols and cell_m must be > 0, got {out}")
    return out


def _check_shape(arr: np.ndarray | None, shape: tuple, where: str, kinds: str = "biuf") -> None:
    """ValueError naming the field when ``arr`` is not of ``kinds`` and ``shape``
    (``None`` in ``shape``: any length)."""
    if arr is None:
        return
    if arr.dtype.kind not in kinds:
        what = "an integer" if kinds == "iu" else "a numeric"
        raise ValueError(f"TrialRecord.{where}: expected {what} array, got dtype {arr.dtype}")
    ok = arr.ndim == len(shape) and all(s is None or s == n for s, n in zip(shape, arr.shape))
    if not ok:
        free = "K" if len(shape) == 1 else "*"
        want = str(tuple(free if s is None else s for s in shape)).replace("'", "")
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
    """Readable entity paths of one method under one trial, and what it has."""

    label: str
    color: tuple[int, int, int]
    base: str
    traces: dict[str, str]  # trace key -> entity path
    statistic: bool = False
    threshold: bool = False  # drawn: finite, and a statistic or score to compare with
    alarms: bool = False
    score: bool = False
    value: bool = False
    track: str | None = None  # TBD track in image coordinates (under .../frames)
    estimate: bool = False

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
    has_xy: bool = False  # truth, measurements or an estimate in metres
    frames: str | None = None  # path of the TBD frames
    truth_track: str | None = None  # path of the true cells, under frames
    image_shape: tuple[int, int] | None = None

    @property
    def trace_paths(self) -> list[str]:
        return [p for m in self.methods for p in m.traces.values()]


def _finite(x: float | None) -> bool:
    return x is not None and math.isfinite(x)


def _layout(rec: TrialRecord) -> _TrialLayout:
    root = entity_root(rec.scenario, rec.snr_db, rec.trial)
    names = method_entity_names(rec.methods, reserved=_ROOT_CHILDREN)
    image = rec.image_shape
    frames_path = f"{root}/frames"
    methods = []
    # Colours follow the sorted labels, so the same configs get the same
    # colour in every trial of a sweep.
    for i, label in enumerate(sorted(rec.methods)):
        tr = rec.methods[label]
        base = f"{root}/{names[label]}"
        tnames = method_entity_names(tr.traces, reserved=_RESERVED)
        traces = {key: f"{base}/{tnames[key]}" for key in tr.traces}
        score = _finite(tr.score)
        methods.append(_MethodLayout(
            label, _PALETTE[i % len(_PALETTE)], base, traces,
            statistic=tr.statistic is not None,
            threshold=_finite(tr.threshold) and (tr.statistic is not None or score),
            alarms=tr.statistic is not None and tr.alarms is not None and bool(tr.alarms.any()),
            score=score,
            value=_held(tr, "value") is not None,
            # Image coordinates need the image height (to put north up).
            track=f"{frames_path}/{names[label]}_track" if tr.track_cells is not None and image else None,
            estimate=tr.estimate_xy is not None,
        ))
    snr = "null" if rec.snr_db is None else f"{rec.snr_db:+g} dB"
    has_frames = _held(rec, "frames") is not None
    return _TrialLayout(
        root=root,
        scenario=rec.scenario,
        title=f"{snr} · trial {rec.trial}",
        sort_key=(rec.scenario, rec.snr_db is None, rec.snr_db or 0.0, rec.trial),
        has_statistic=any(m.statistic for m in methods),
        methods=tuple(methods),
        has_xy=rec.truth_xy is not None or rec.measurements_xy is not None or any(m.estimate for m in methods),
        frames=frames_path if has_frames else None,
        truth_track=f"{frames_path}/truth_track" if rec.truth_cells is not None and image else None,
        image_shape=image,
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


def _cell_pixels(cells: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Pixel centres ``(col + 0.5, rows - row - 0.5)`` of (row, col) cells in
    the north-up image; NaN rows for cells outside the grid."""
    rows, cols = shape
    r, c = cells[:, 0].astype(np.float64), cells[:, 1].astype(np.float64)
    out = np.column_stack([c + 0.5, rows - r - 0.5]).astype(np.float32)
    out[~((r >= 0) & (r < rows) & (c >= 0) & (c < cols))] = np.nan
    return out


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


def _log_points(stream, path: str, t: np.ndarray, pos: np.ndarray, color, radius: float) -> np.ndarray:
    """One Points2D per step with finite (screen) coordinates; returns those steps."""
    import rerun as rr

    steps = np.flatnonzero(np.isfinite(pos).all(axis=1))
    if steps.size == 0:
        return steps
    path = rerun_path(path)
    ui = rr.components.Radius.ui_points(radius)
    stream.log(path, rr.Points2D.from_fields(colors=[color], radii=[ui]), static=True)
    stream.send_columns(
        path, indexes=_indexes(steps, t),
        columns=rr.Points2D.columns(positions=pos[steps]),
    )
    return steps


def _log_track(stream, path: str, t: np.ndarray, pos: np.ndarray, color, radius: float = 5.0) -> None:
    """Current position per step plus the whole track as a static line
    (``pos`` in screen coordinates: north-up metres or image pixels)."""
    import rerun as rr

    steps = _log_points(stream, path, t, pos, color, radius=radius)
    if steps.size:
        stream.log(
            rerun_path(path),
            rr.LineStrips2D([pos[steps]], colors=[color],
                            radii=[rr.components.Radius.ui_points(1.0)]),
            static=True,
        )


def _log_measurements(stream, root: str, t: np.ndarray, xy: np.ndarray, flags: np.ndarray | None) -> None:
    """Current measurement per step, all of them as a static cloud, and the
    glint-flagged ones as a static cloud of their own colour."""
    import rerun as rr

    pos = _north_up(xy)
    steps = _log_points(stream, f"{root}/measurements", t, pos, _MEASUREMENT_COLOR, radius=4.0)
    if not steps.size:
        return
    # Child entities: static positions on `measurements` itself would
    # shadow the per-step ones.
    dim = (*_MEASUREMENT_COLOR, 110)
    stream.log(
        rerun_path(f"{root}/measurements/all"),
        rr.Points2D(pos[steps], colors=[dim], radii=[rr.components.Radius.ui_points(2.0)]),
        static=True,
    )
    if flags is not None:
        glint = np.intersect1d(steps, np.flatnonzero(flags))
        if glint.size:
            stream.log(
                rerun_path(f"{root}/measurements/glint"),
                rr.Points2D(pos[glint], colors=[_GLINT_COLOR],
                            radii=[rr.components.Radius.ui_points(4.5)]),
                static=True,
            )


def _quant_info(q: Quantised, grid: dict | None = None):
    """Static AnyValues explaining the codes of a quantised image."""
    import rerun as rr

    info = {"code_lo": q.lo, "code_hi": q.hi,
            "codes": "0 = non-finite; value = code_lo + (code - 1) * (code_hi - code_lo) / 254",
            "orientation": "north up: grid row r is image row rows-1-r"}
    if grid is not None:
        info.update({f"grid_{k}": v for k, v in grid.items()})
    return rr.AnyValues(**info)


def _image_format(shape: tuple[int, int]):
    import rerun as rr

    return rr.components.ImageFormat(width=int(shape[1]), height=int(shape[0]),
                                     channel_datatype=rr.ChannelDatatype.U8)


def _log_frames(stream, layout: _TrialLayout, rec: TrialRecord, t: np.ndarray) -> None:
    """TBD frames: one DepthImage column over the steps, plus the true cells."""
    import rerun as rr

    q = _quantised(rec, "frames")
    k = q.codes.shape[0]
    if k == 0 or q.codes.size == 0:
        return
    path = rerun_path(layout.frames)
    stream.log(path, rr.DepthImage.from_fields(
        format=_image_format(q.codes.shape[1:]), colormap=_FRAMES_COLORMAP,
        depth_range=(1.0, 255.0), meter=1.0), static=True)
    stream.log(path, _quant_info(q, rec.grid), static=True)
    # Flip rows: north up (see the module docstring).
    codes = np.ascontiguousarray(q.codes[:, ::-1, :]).reshape(k, -1)
    stream.send_columns(path, indexes=_indexes(np.arange(k), t),
                        columns=rr.DepthImage.columns(buffer=codes))
    if layout.truth_track:
        _log_track(stream, layout.truth_track, t, _cell_pixels(rec.truth_cells, layout.image_shape),
                   _TRUTH_COLOR, radius=3.0)


def _log_value(stream, path: str, q: Quantised) -> None:
    """A TBD merit map: static DepthImage of its codes, north up."""
    import rerun as rr

    if q.codes.size == 0:
        return
    path = rerun_path(path)
    stream.log(path, rr.DepthImage(np.ascontiguousarray(q.codes[::-1, :]), colormap=_VALUE_COLORMAP,
                                   depth_range=(1.0, 255.0), meter=1.0), static=True)
    stream.log(path, _quant_info(q), static=True)


def _log_method(stream, m: _MethodLayout, tr: MethodTrace, t: np.ndarray,
                image_shape: tuple[int, int] | None = None) -> None:
    """Statistic, threshold, alarms, score, traces, estimate and TBD track/value of one method."""
    import rerun as rr

    k = t.shape[0]
    every = np.arange(k)
    if m.statistic:
        _log_series(stream, m.path("statistic"), t, every, tr.statistic,
                    rr.SeriesLines(names=m.label, colors=[m.color], widths=[1.5]))
    if m.score:
        # A scene-level number: a flat line, to compare with the threshold.
        _log_series(stream, m.path("score"), t, every, np.full(k, tr.score),
                    rr.SeriesLines(names=f"{m.label} score", colors=[m.color], widths=[2.0]))
    if m.threshold:
        # Lighter and thinner than the statistic: a reference line.
        _log_series(stream, m.path("threshold"), t, every, np.full(k, tr.threshold),
                    rr.SeriesLines(names=f"{m.label} threshold", colors=[(*m.color, 150)],
                                   widths=[1.0]))
    if m.alarms:
        hits = np.flatnonzero(tr.alarms)
        _log_series(stream, m.path("alarms"), t, hits, tr.statistic[hits],
                    rr.SeriesPoints(names=f"{m.label} alarms", colors=[m.color],
                                    markers=["cross"], marker_sizes=[5.0]))
    for key, path in m.traces.items():
        _log_series(stream, path, t, every, tr.traces[key],
                    rr.SeriesLines(names=f"{m.label} {key}", colors=[m.color], widths=[1.0]))
    if m.estimate:
        _log_track(stream, m.path("estimate"), t, _north_up(tr.estimate_xy), m.color)
    if m.track:
        _log_track(stream, m.track, t, _cell_pixels(tr.track_cells, image_shape), m.color, radius=3.0)
    if m.value:
        _log_value(stream, m.path("value"), _quantised(tr, "value"))


def _log_record(rec: TrialRecord, stream, layout: _TrialLayout | None = None) -> _TrialLayout:
    """Log one trial into ``stream``; returns its layout (for the blueprint)."""
    layout = layout or _layout(rec)
    t = np.asarray(rec.t, dtype=np.float64)
    if rec.truth_xy is not None:
        _log_track(stream, f"{layout.root}/truth", t, _north_up(rec.truth_xy), _TRUTH_COLOR)
    if rec.measurements_xy is not None:
        _log_measurements(stream, layout.root, t, rec.measurements_xy, rec.measurement_flags)
    if layout.frames:
        _log_frames(stream, layout, rec, t)
    for m in layout.methods:
        _log_method(stream, m, rec.methods[m.label], t, layout.image_shape)
    return layout


def _log_records(records: Iterable[TrialRecord], stream,
                 layouts: list[_TrialLayout] | None = None) -> list[_TrialLayout]:
    """Log records, flushing every FLUSH_EVERY (and after every record with
    frames: megabytes each) to keep the sink queue short."""
    out = []
    for i, rec in enumerate(records, start=1):
        out.append(_log_record(rec, stream, layouts[i - 1] if layouts else None))
        if i % FLUSH_EVERY == 0 or out[-1].frames:
            stream.flush()
    return out


# --------------------------------------------------------------------------
# Summary (static, so it shows on any timeline)
# --------------------------------------------------------------------------

_TABLE_COLUMNS = [
    "scenario", "method", "snr_db", "n_trials", "pd", "pd_low", "pd_high",
    "pfa", "pfa_low", "pfa_high", "delay_mean", "rmse_mean", "rmse_low", "rmse_high",
    "divergence_rate", "nees_mean",
]

#: Summary bar charts: (summary column, entity root, view title).
_CHARTS = (
    ("pd", "/summary/pd_vs_snr", "Pd vs SNR (dB)"),
    ("rmse_mean", "/summary/rmse_vs_snr", "RMSE (m) vs SNR (dB)"),
)


def _curves(summary: pd.DataFrame, column: str, root: str) -> list[tuple[str, tuple, pd.DataFrame]]:
    """(entity path, colour, rows sorted by SNR) per curve with data in ``column``.

    One curve per method, or per (scenario, method) when the summary mixes
    scenarios. Colours follow the sorted labels, as in the trial plots.
    """
    if column not in summary.columns:
        return []
    df = summary.dropna(subset=["snr_db", column])
    multi = "scenario" in df.columns and df["scenario"].nunique() > 1
    groups = list(df.groupby(["scenario", "method"] if multi else ["method"], sort=False))
    labels = sorted({str(key[-1]) for key, _ in groups})  # keys are tuples (list `by`)
    names = method_entity_names(labels)
    out = []
    for key, rows in groups:
        label = str(key[-1])
        scope = f"{entity_name(str(key[0]))}/" if multi else ""
        color = _PALETTE[labels.index(label) % len(_PALETTE)]
        out.append((f"{root}/{scope}{names[label]}", color, rows.sort_values("snr_db")))
    return out


def _log_bars(stream, curves: list, column: str) -> None:
    """Grouped bars: one BarChart per curve, shifted so bars sit side by side.

    A BarChart is static and needs no timeline; its legend entry is the entity
    name (BarChart has no series name).
    """
    import rerun as rr

    if not curves:
        return
    snrs = np.unique(np.concatenate([rows["snr_db"].to_numpy(float) for _, _, rows in curves]))
    step = float(np.min(np.diff(snrs))) if snrs.size > 1 else 1.0
    width = 0.8 * step / len(curves)
    for i, (path, color, rows) in enumerate(curves):
        x = rows["snr_db"].to_numpy(float) + (i - (len(curves) - 1) / 2) * width
        stream.log(
            rerun_path(path),
            rr.BarChart(rows[column].to_numpy(float), abscissa=x,
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


def _markdown_table(df: pd.DataFrame) -> str:
    cols = [str(c) for c in df.columns]
    lines = ["| " + " | ".join(_cell(c) for c in cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(_cell(v) for v in row) + " |" for row in df.itertuples(index=False)]
    return "\n".join(lines)


def _summary_markdown(summary: pd.DataFrame) -> str:
    """A compact pivot (SNR x method) of Pd and of RMSE, then the key columns of every row."""
    parts = ["# Summary"]
    for column, title in (("pd", "Pd"), ("rmse_mean", "RMSE (m)")):
        if column not in summary.columns:
            continue
        df = summary.dropna(subset=["snr_db", column])
        if not df.empty and ("scenario" not in df.columns or df["scenario"].nunique() <= 1):
            pivot = df.pivot_table(index="snr_db", columns="method", values=column, sort=False)
            pivot = pivot.sort_index().reset_index()
            parts += [f"## {title} by SNR (dB)", _markdown_table(pivot)]
    cols = [c for c in _TABLE_COLUMNS if c in summary.columns]
    parts += ["## All rows", _markdown_table(summary[cols])]
    return "\n\n".join(parts) + "\n"


def _summary_charts(summary: pd.DataFrame | None) -> tuple[tuple[str, str], ...] | None:
    """None for no/empty summary, else the (entity root, title) of each bar
    chart with data (possibly none: the table alone). ValueError when
    ``method`` or ``snr_db`` is missing."""
    if summary is None or summary.empty:
        return None
    missing = {"method", "snr_db"} - set(summary.columns)
    if missing:
        raise ValueError(f"summary: missing column(s) {', '.join(sorted(missing))}")
    return tuple((root, title) for column, root, title in _CHARTS if _curves(summary, column, root))


def _log_summary(stream, summary: pd.DataFrame | None) -> tuple[tuple[str, str], ...] | None:
    """Pd / RMSE vs SNR bars and a Markdown table; returns the charts logged
    (see :func:`_summary_charts`), None when there is no summary."""
    import rerun as rr

    charts = _summary_charts(summary)
    if charts is None:
        return None
    for column, root, _ in _CHARTS:
        _log_bars(stream, _curves(summary, column, root), column)
    stream.log("/summary/table", rr.TextDocument(_summary_markdown(summary),
                                                 media_type=rr.MediaType.MARKDOWN), static=True)
    return charts


# --------------------------------------------------------------------------
# Default blueprint
# --------------------------------------------------------------------------


def _trace_views(layout: _TrialLayout, rel) -> list:
    """One time-series view per trace name (``error_x`` of every method
    together), or a single one when there are many names."""
    import rerun.blueprint as rrb

    by_key: dict[str, list[str]] = {}
    for m in layout.methods:
        for key, path in m.traces.items():
            by_key.setdefault(key, []).append(rel(path))
    if not by_key:
        return []
    origin = rerun_path(layout.root)
    if len(by_key) > _MAX_TRACE_VIEWS:
        return [rrb.TimeSeriesView(origin=origin, name="traces", contents=[p for v in by_key.values() for p in v])]
    return [rrb.TimeSeriesView(origin=origin, name=key, contents=paths) for key, paths in by_key.items()]


def _image_views(layout: _TrialLayout, rel) -> list:
    """The frames with every track, then each method's value map with its track."""
    import rerun.blueprint as rrb

    origin = rerun_path(layout.root)
    views = [rrb.Spatial2DView(origin=rerun_path(layout.frames), name="frames (north up)")] if layout.frames else []
    for m in layout.methods:
        if m.value:
            contents = [rel(m.path("value"))] + ([rel(m.track)] if m.track else [])
            views.append(rrb.Spatial2DView(origin=origin, name=f"{m.label} value", contents=contents))
    return views


def _trial_tab(layout: _TrialLayout, title: str):
    """Detection: statistics on top, track and traces below. TBD: frames and
    value maps on top, scores and traces below. Tracking: the track on top,
    one error series view per trace name below."""
    import rerun.blueprint as rrb

    origin = rerun_path(layout.root)
    # Explicit paths: entity filters only support a trailing /**, and
    # $origin spares us re-escaping the root.
    rel = lambda p: "+ $origin" + rerun_path(p)[len(origin):]
    top, bottom = [], []
    if layout.has_statistic:
        stats = [rel(m.path(c)) for m in layout.methods for c in ("statistic", "threshold", "alarms")
                 if getattr(m, c)]
        top.append(rrb.TimeSeriesView(origin=origin, name="statistics", contents=stats))
    if layout.frames or any(m.value for m in layout.methods):
        images = _image_views(layout, rel)
        top.append(rrb.Grid(*images) if len(images) > 3 else rrb.Horizontal(*images))
    elif layout.has_xy:
        bottom.append(rrb.Spatial2DView(origin=origin, name="track (north up)"))
    scores = [rel(m.path(c)) for m in layout.methods if m.score for c in ("score", "threshold")
              if c == "score" or m.threshold]
    if scores and not layout.has_statistic:
        bottom.append(rrb.TimeSeriesView(origin=origin, name="scores", contents=scores))
    bottom += _trace_views(layout, rel)
    if not top and bottom:
        top.append(bottom.pop(0))  # tracking: the track gets the large row
    if not top:
        return rrb.Spatial2DView(origin=origin, name=title)
    if not bottom:
        return rrb.Vertical(*top, name=title)
    # More than three views side by side are too narrow: a grid instead.
    row = bottom[0] if len(bottom) == 1 else rrb.Horizontal(*bottom) if len(bottom) <= 3 else rrb.Grid(*bottom)
    return rrb.Vertical(*top, row, name=title, row_shares=[3] * len(top) + [2])


def _summary_tab(charts: tuple[tuple[str, str], ...]):
    import rerun.blueprint as rrb

    views = [rrb.BarChartView(origin=root, name=title) for root, title in charts]
    views.append(rrb.TextDocumentView(origin="/summary/table", name="summary"))
    return rrb.Horizontal(*views, column_shares=[3] * len(charts) + [2], name="summary")


def _blueprint(layouts: list[_TrialLayout], charts: tuple | None):
    """Tabs: the first MAX_TABS trials (by scenario, SNR, trial), then the
    summary (``charts`` from :func:`_summary_charts`; None: no summary tab)."""
    import rerun.blueprint as rrb

    chosen = sorted(layouts, key=lambda lay: lay.sort_key)[:MAX_TABS]
    several = len({lay.scenario for lay in layouts}) > 1
    tabs = [_trial_tab(lay, f"{lay.scenario} {lay.title}" if several else lay.title) for lay in chosen]
    if charts is not None:
        tabs.append(_summary_tab(charts))
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
    summary: pd.DataFrame | None = None,
    *,
    recording_id: str,
    application_id: str = "radar-bench",
) -> Path:
    """Write ``records`` (and the ``summary`` curves) to an ``.rrd`` file.

    Atomic: the file is written to ``path.with_suffix(".rrd.tmp")`` and renamed
    only once complete (footer written), so a crash never leaves a truncated
    ``recording.rrd``. ``summary`` needs columns ``method`` and ``snr_db``;
    ``pd`` and ``rmse_mean`` (either, both or none; NaN rows skipped) become
    bar charts, every row goes into the table. Returns ``path``.
    """
    import rerun as rr

    path = Path(path)
    tmp = path.with_suffix(".rrd.tmp")
    tmp.parent.mkdir(parents=True, exist_ok=True)
    records = list(records)  # iterated twice: blueprint, then logging
    layouts = [_layout(r) for r in records]  # fails on bad names before any I/O
    charts = _summary_charts(summary)
    stream = rr.RecordingStream(application_id, recording_id=recording_id)
    try:
        # The sink (and its blueprint) must be attached before logging.
        stream.save(tmp, default_blueprint=_blueprint(layouts, charts))
        try:
            _log_records(records, stream, layouts)
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
    def from_stream(cls, stream) -> LiveViewer:
        """Wrap a stream whose sink is already set (an existing viewer via
        ``connect_grpc``, a file in tests) instead of spawning a viewer."""
        self = cls.__new__(cls)
        self._attach(stream)
        return self

    def _attach(self, stream) -> None:
        self._stream = stream
        self._layouts: list[_TrialLayout] = []
        self._summary: tuple | None = None  # charts of the logged summary
        self._shown: tuple | None = None

    def log_records(self, records: Iterable[TrialRecord]) -> None:
        """Log records now (the viewer shows them as they arrive)."""
        self._layouts += _log_records(records, self._stream)
        self._send_blueprint()

    def log_summary(self, summary: pd.DataFrame | None) -> None:
        """Log the Pd / RMSE vs SNR bars and table, and add the summary tab."""
        charts = _log_summary(self._stream, summary)
        if charts is not None:
            self._summary = charts
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

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
