"""The recorded trial: what a worker keeps of one selected trial, and its bytes.

Workers build one :class:`TrialRecord` per selected trial (``[record] trials``
per SNR level) and send it to the driver as bytes (:meth:`TrialRecord.to_bytes`,
also what the store keeps); only the driver draws it (:mod:`bench.recording.sinks`).
This module must never import rerun: workers import it, and ``import rerun``
costs about half a second per process.

The record is generic (docs/architecture.md, 'Recordings'). The harness fills
what every task shares: the step times, the true and measured positions in the
plane and, per method config, the threshold in force and extra per-step series
(``traces``). Each task (:mod:`bench.tasks`) adds what it draws, on the trial
and on each method, in three containers:

* ``arrays``: exact per-step arrays, first axis K (a detector's statistic, a
  tracker's estimate, the cells of a TBD track);
* ``images``: arrays kept as uint8 codes (:class:`Quantised`: TBD frames and
  value maps, 4x smaller than float32);
* ``info``: JSON values (a grid, a scene score).

Quantisation: each image gets its own range ``[lo, hi]`` with
``lo = max(min, mean - 3·std)`` and ``hi = min(max, mean + 6·std)`` over its
finite values (a trial's frames share one range). Values are clipped to the
range and mapped linearly to codes 1..255 (``value = lo + (code - 1)·(hi - lo)/254``,
error ≤ (hi - lo)/508, about 0.02 std); code 0 marks a non-finite value. A
500×500×20 trial is 5 MB of codes instead of 20 MB of float32.

Byte format, version 3: a compressed ``.npz`` of the arrays plus a JSON header
(no pickle). Trial-level arrays and images are stored under their names,
method ``i``'s under ``m{i}_{name}`` and its traces under ``m{i}_trace{j}``;
labels and trace names live in the header, so any label is valid. Versions 1
and 2 (named fields per task) still load, mapped onto the containers.
"""

from __future__ import annotations

import io
import json
import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: this module computes stored numbers: its code belongs to the identity of every config
#: that loads it (docs/architecture.md, 'Identities')
COMPUTES_RESULTS = True

__all__ = ["MethodTrace", "Quantised", "TrialRecord", "check_shape"]

#: Bumped when the byte layout of :meth:`TrialRecord.to_bytes` changes.
_FORMAT_VERSION = 3
_READABLE_VERSIONS = frozenset({1, 2, 3})
#: Quantisation range, in standard deviations below / above the mean.
QUANT_SIGMAS = (3.0, 6.0)
#: What a container name must look like (it becomes an npz key).
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")
#: npz keys of the trial that its own containers must not take.
_TRIAL_KEYS = frozenset({"t", "header", "truth_xy", "measurements_xy"})
_METHOD_PREFIX = re.compile(r"m\d")
_TRACE_KEY = re.compile(r"trace\d+\Z")


# --------------------------------------------------------------------------
# Quantised arrays
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


# --------------------------------------------------------------------------
# Containers shared by the trial and its methods
# --------------------------------------------------------------------------


@dataclass(eq=False, kw_only=True)
class _Payload:
    """The task-owned containers: exact per-step ``arrays``, quantised
    ``images`` and JSON ``info``."""

    arrays: dict[str, np.ndarray] = field(default_factory=dict)
    images: dict[str, Any] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)

    def _normalise_payload(self) -> None:
        self.arrays = {str(k): np.asarray(v) for k, v in self.arrays.items()}
        self.images = {str(k): v if isinstance(v, Quantised) else np.asarray(v) for k, v in self.images.items()}
        self.info = dict(self.info)

    def image(self, name: str) -> np.ndarray | None:
        """Image ``name`` as float values (dequantised on every call when it
        came from bytes); None when absent."""
        held = self.images.get(name)
        return held.values() if isinstance(held, Quantised) else held

    def quantised(self, name: str) -> Quantised | None:
        """Image ``name`` as codes (quantised now if it is still an array)."""
        held = self.images.get(name)
        return held if held is None or isinstance(held, Quantised) else Quantised.of(held)

    def image_shape(self, name: str) -> tuple[int, ...] | None:
        held = self.images.get(name)
        return None if held is None else tuple(held.shape)

    def _check_payload(self, k: int, where: str, reserved=frozenset(), forbidden=None) -> None:
        for name in [*self.arrays, *self.images]:
            if not _NAME.match(name) or name in reserved or (forbidden and forbidden.match(name)):
                raise ValueError(f"TrialRecord.{where}arrays: {name!r} is not a usable array name")
        both = set(self.arrays) & set(self.images)
        if both:
            raise ValueError(f"TrialRecord.{where}images: {sorted(both)} are both an array and an image")
        for name, arr in self.arrays.items():       # per step: first axis K
            check_shape(arr, (k, *[None] * (arr.ndim - 1)), f"{where}arrays[{name!r}]")
        for name, img in self.images.items():       # any shape, numeric
            codes = img.codes if isinstance(img, Quantised) else img
            check_shape(codes, (None,) * codes.ndim, f"{where}images[{name!r}]")

    def _steps_of_arrays(self, keep: np.ndarray) -> dict:
        """The payload's containers with every per-step array cut to the steps ``keep`` (K,) bool."""
        return {"arrays": {name: arr[keep] for name, arr in self.arrays.items()}, "images": dict(self.images),
                "info": dict(self.info)}

    def _pack(self, prefix: str, npz: dict, meta: dict) -> None:
        meta["has"] = meta.get("has", []) + list(self.arrays)
        for name, arr in self.arrays.items():
            npz[prefix + name] = arr
        meta["images"] = {}
        for name in self.images:
            q = self.quantised(name)
            npz[prefix + name] = q.codes
            meta["images"][name] = [q.lo, q.hi]
        meta["info"] = self.info


def _unpack(z, prefix: str, meta: dict, skip=()) -> dict:
    """The ``arrays``/``images``/``info`` of a payload stored by ``_pack``."""
    return {"arrays": {k: z[prefix + k] for k in meta.get("has", []) if k not in skip},
            "images": {k: Quantised(z[prefix + k], float(lo), float(hi)) for k, (lo, hi) in meta["images"].items()},
            "info": meta["info"]}


# --------------------------------------------------------------------------
# Data carried from workers to the driver
# --------------------------------------------------------------------------


@dataclass(eq=False)
class MethodTrace(_Payload):
    """What one method config produced on one recorded trial.

    threshold : float or None — the threshold in force (nominal or calibrated);
        ``None`` or non-finite: not drawn.
    traces : name -> (K,) float — extra series drawn as time series by the
        harness (e.g. a whitened innovation, a tracker's ``error_x`` in metres).
    arrays, images, info : what the method's task keeps (see the module docstring).
    """

    threshold: float | None = None
    traces: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        # Normalised here so the byte round trip is exact whatever the worker passed.
        if self.threshold is not None:
            self.threshold = float(self.threshold)
        self.traces = {str(k): np.asarray(v) for k, v in self.traces.items()}
        self._normalise_payload()

    def at_steps(self, keep: np.ndarray) -> MethodTrace:
        """The trace on the steps ``keep`` (K,) bool only (:meth:`TrialRecord.at_steps`)."""
        return MethodTrace(threshold=self.threshold, traces={name: v[keep] for name, v in self.traces.items()},
                           **self._steps_of_arrays(keep))

    def check(self, k: int, where: str) -> None:
        """Raise ValueError if an array does not fit ``K = k`` steps."""
        self._check_payload(k, f"{where}.", forbidden=_TRACE_KEY)
        for name, arr in self.traces.items():
            check_shape(arr, (k,), f"{where}.traces[{name!r}]")


@dataclass(eq=False)
class TrialRecord(_Payload):
    """Everything recorded for one selected trial.

    scenario : registry name or config label, e.g. ``"cv-turn-cv"``.
    snr_db : SNR of the trial's level; ``None`` for a null-hypothesis trial.
    trial : global trial index within its SNR level.
    t : (K,) seconds.
    truth_xy, measurements_xy : (K, 2) metres or None (NaN rows allowed: not
        drawn, e.g. missed detections).
    methods : method config label (e.g. ``"cumulant[window=32]"``) -> trace.
    arrays, images, info : what the tasks keep of the scene (see the module docstring).
    """

    scenario: str
    snr_db: float | None
    trial: int
    t: np.ndarray
    truth_xy: np.ndarray | None = None
    measurements_xy: np.ndarray | None = None
    methods: dict[str, MethodTrace] = field(default_factory=dict)

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
        self._normalise_payload()
        self._check()

    @property
    def steps(self) -> int:
        return int(self.t.shape[0])

    def at_steps(self, keep: np.ndarray) -> TrialRecord:
        """The record on the steps ``keep`` (K,) bool only: a trial of a ragged batch
        drawn on the steps it has (docs/architecture.md, 'Ragged batches'). Every
        per-step array (first axis K) is cut; images and info are kept whole."""
        keep = np.asarray(keep, dtype=bool)

        def cut(a):
            return None if a is None else a[keep]
        return TrialRecord(self.scenario, self.snr_db, self.trial, self.t[keep], truth_xy=cut(self.truth_xy),
                           measurements_xy=cut(self.measurements_xy),
                           methods={label: m.at_steps(keep) for label, m in self.methods.items()},
                           **self._steps_of_arrays(keep))

    def has_images(self) -> bool:
        """Whether the trial or a method holds images (megabytes: worth a flush)."""
        return bool(self.images) or any(m.images for m in self.methods.values())

    def _check(self) -> None:
        # Fail in the worker, where the bug is, not later in the driver.
        check_shape(self.t, (None,), "t")
        k = self.steps
        check_shape(self.truth_xy, (k, 2), "truth_xy")
        check_shape(self.measurements_xy, (k, 2), "measurements_xy")
        self._check_payload(k, "", reserved=_TRIAL_KEYS, forbidden=_METHOD_PREFIX)
        for label, trace in self.methods.items():
            trace.check(k, f"methods[{label!r}]")

    # -- serialisation -----------------------------------------------------

    def to_bytes(self) -> bytes:
        """Compressed ``.npz`` bytes: arrays plus a JSON header (no pickle)."""
        npz: dict[str, np.ndarray] = {"t": self.t}
        header: dict = {"version": _FORMAT_VERSION, "scenario": self.scenario, "snr_db": self.snr_db,
                        "trial": self.trial,
                        "has": [k for k in ("truth_xy", "measurements_xy") if getattr(self, k) is not None]}
        for key in header["has"]:
            npz[key] = getattr(self, key)
        self._pack("", npz, header)
        methods = []
        for i, (label, tr) in enumerate(self.methods.items()):
            meta = {"label": label, "threshold": tr.threshold, "traces": list(tr.traces)}
            tr._pack(f"m{i}_", npz, meta)
            for j, arr in enumerate(tr.traces.values()):
                npz[f"m{i}_trace{j}"] = arr
            methods.append(meta)
        header["methods"] = methods
        # JSON floats are written with repr(), so they round-trip exactly
        # (inf/nan included, as Python's json writes them).
        npz["header"] = np.frombuffer(json.dumps(header, default=_json_value).encode("utf-8"), dtype=np.uint8)
        buf = io.BytesIO()
        np.savez_compressed(buf, **npz)
        return buf.getvalue()

    @classmethod
    def from_bytes(cls, data: bytes) -> TrialRecord:
        """Inverse of :meth:`to_bytes` (reads format versions 1 to 3)."""
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            header = json.loads(z["header"].tobytes().decode("utf-8"))
            if header.get("version") not in _READABLE_VERSIONS:
                raise ValueError(f"TrialRecord bytes: unsupported version {header.get('version')!r}")
            if header["version"] < 3:
                header = _from_version_2(header)
            methods = {}
            for i, meta in enumerate(header["methods"]):
                traces = {name: z[f"m{i}_trace{j}"] for j, name in enumerate(meta["traces"])}
                methods[meta["label"]] = MethodTrace(threshold=meta["threshold"], traces=traces,
                                                     **_unpack(z, f"m{i}_", meta))
            has = header["has"]
            return cls(scenario=header["scenario"], snr_db=header["snr_db"], trial=header["trial"], t=z["t"],
                       truth_xy=z["truth_xy"] if "truth_xy" in has else None,
                       measurements_xy=z["measurements_xy"] if "measurements_xy" in has else None,
                       methods=methods, **_unpack(z, "", header, skip=("truth_xy", "measurements_xy")))


def _from_version_2(header: dict) -> dict:
    """A version 1 or 2 header in the version 3 form. Those versions named
    every task's field; their arrays keep their npz keys, the grid and the
    scene score become ``info``, the frames and value maps ``images``."""
    header = dict(header)
    header.setdefault("has", ["truth_xy", "measurements_xy"])   # version 1: always both
    header["images"] = {"frames": header["frames_range"]} if "frames_range" in header else {}
    header["info"] = {"grid": header["grid"]} if header.get("grid") is not None else {}
    methods = []
    for meta in header["methods"]:
        meta = dict(meta)
        meta["images"] = {"value": meta["value_range"]} if "value_range" in meta else {}
        meta["info"] = {"score": meta["score"]} if meta.get("score") is not None else {}
        methods.append(meta)
    header["methods"] = methods
    return header


def _json_value(x):
    """JSON form of the numpy values a task may put in ``info``."""
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(f"TrialRecord.info: {type(x).__name__} is not JSON serialisable")


def check_shape(arr: np.ndarray | None, shape: tuple, where: str, kinds: str = "biuf") -> None:
    """ValueError naming the field when ``arr`` is not of ``kinds`` and ``shape``
    (``None`` in ``shape``: any length). Tasks use it on what they record."""
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
