"""The span bank of scenario ``recorded-tracks``: every track cut into spans on the fixed
step, their smoothed states, gaps, and where each maneuvers (the segments a batch draws
from), built once per parameter set (docs/recorded-tracks.md)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.signal import savgol_filter

from radarbench.bench.errors import ConfigError
from radarbench.scenarios.recorded_tracks.files import TIME, TRACK, checked_tracks, read_file, read_sample


@dataclass(frozen=True)
class Bank:
    """Every track resampled on the scenario's grid, spans concatenated: position,
    velocity, acceleration (M, 2) each, the maneuver indicator (M,) (False at a
    missing step), whether each step was recorded (M,), and the first
    step of every segment with a maneuver onset at ``onset_step`` (``onsets``) or
    without a maneuver (``quiet``)."""
    pos: np.ndarray
    vel: np.ndarray
    acc: np.ndarray
    maneuvering: np.ndarray
    onsets: np.ndarray
    quiet: np.ndarray
    spans: int
    #: (M,) bool: False at the steps inside a masked gap (``masked_gap_s``) and, replaying, at
    #: the steps without a recorded measurement; True elsewhere
    valid: np.ndarray
    #: (M, 2) replaying: the recorded measurement of each step (NaN where none); else None
    z: np.ndarray | None = None
    #: what reading the file converted, for the user (:func:`files.read_file`)
    notes: tuple[str, ...] = ()


def _span_states(t: np.ndarray, xy: np.ndarray, dt: float, window: int) -> np.ndarray:
    """(k, 3, 2) position, velocity, acceleration on the grid t0 + dt j inside the span: the
    recorded positions interpolated linearly onto the grid, then a Savitzky-Golay filter of
    ``window`` steps (a local least-squares cubic, its value and first two derivatives)."""
    grid = t[0] + dt * np.arange(int(math.floor((t[-1] - t[0]) / dt + 1e-9)) + 1)
    on_grid = np.stack([np.interp(grid, t, xy[:, axis]) for axis in range(2)], axis=-1)
    return np.stack([savgol_filter(on_grid, window, 3, deriv=order, delta=dt, axis=0, mode="interp")
                     for order in range(3)], axis=1)


def _gap_steps(t: np.ndarray, dt: float, steps: int, max_gap_s: float) -> np.ndarray:
    """(steps,) bool: the grid steps t0 + dt j strictly inside a recorded gap over
    ``max_gap_s`` (no point of the track near them: missing, not interpolated)."""
    grid = t[0] + dt * np.arange(steps)
    after = np.clip(np.searchsorted(t, grid, side="right"), 1, len(t) - 1)   # t[after - 1] <= grid < t[after]
    return (grid > t[after - 1]) & (grid < t[after]) & (t[after] - t[after - 1] > max_gap_s)


def _on_grid(t: np.ndarray, z: np.ndarray, dt: float, steps: int) -> np.ndarray:
    """(steps, 2) recorded measurements on the grid t0 + dt j: each sample on its nearest
    step, the first sample where two fall on one step, NaN on a step with none."""
    step = np.rint((t - t[0]) / dt).astype(np.int64)
    keep = step < steps                                  # the grid ends at or before the last sample
    first = np.unique(step[keep], return_index=True)[1]  # times increase: the earliest sample of each step
    out = np.full((steps, 2), np.nan)
    out[step[keep][first]] = z[keep][first]
    return out


def maneuver_size(states: np.ndarray, measure: str) -> np.ndarray:
    """(M,) per step: |a| (m/s^2), or the turn rate |v x a| / |v|^2 in deg/s (0 below 1 m/s,
    where a heading is not defined: a hovering helicopter does not turn)."""
    (vx, vy), (ax, ay) = states[:, 1].T, states[:, 2].T
    if measure == "acceleration":
        return np.hypot(ax, ay)
    speed_sq = vx * vx + vy * vy
    rate = np.abs(vx * ay - vy * ax) / np.maximum(speed_sq, 1.0)
    return np.where(speed_sq >= 1.0, np.rad2deg(rate), 0.0)


def maneuver_threshold(p) -> float:
    return p.maneuver_threshold_m_s2 if p.maneuver_measure == "acceleration" else p.turn_rate_threshold_deg_s


def smoothing_steps(p) -> int:
    """The Savitzky-Golay window in steps: ``smoothing_s`` rounded to an odd count, five at least."""
    return max(5, 2 * int(round(p.smoothing_s / p.dt_s / 2.0)) + 1)


def _runs_at_least(flags: np.ndarray, boundary: np.ndarray, length: int) -> np.ndarray:
    """``flags`` with its runs of True shorter than ``length`` steps cleared; a run ends at a
    span boundary (``boundary`` True at each span's first step)."""
    start = flags & (boundary | ~np.r_[False, flags[:-1]])
    run_id = np.cumsum(start) * flags
    sizes = np.bincount(run_id)
    return flags & (sizes[run_id] >= length)


def build_bank(p) -> Bank:
    """The resampled tracks of config ``p`` and the segments a trial can draw
    (docstring of :class:`RecordedTracks`)."""
    table, notes = load_tracks(p)
    window = smoothing_steps(p)
    parts, boundary, recorded, measured = [], [], [], []
    for _, track in table.groupby(TRACK, sort=False):
        t, xy = track[TIME].to_numpy(), track[["east", "north"]].to_numpy()
        z = track[["meas_east", "meas_north"]].to_numpy() if replays(p) else None
        cuts = np.flatnonzero(np.diff(t) > max(p.max_gap_s, p.masked_gap_s)) + 1
        for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(t)]):
            if t[b - 1] - t[a] >= (max(p.steps, window) - 1) * p.dt_s:
                states = _span_states(t[a:b], xy[a:b], p.dt_s, window)
                parts.append(states)
                boundary.append(np.r_[True, np.zeros(len(states) - 1, bool)])
                recorded.append(~_gap_steps(t[a:b], p.dt_s, len(states), p.max_gap_s))
                if z is not None:
                    measured.append(_on_grid(t[a:b], z[a:b], p.dt_s, len(states)))
    if not parts:
        ends = f"masked_gap_s = {p.masked_gap_s:g} s" if masks_gaps(p) else f"max_gap_s = {p.max_gap_s:g} s"
        raise ConfigError("steps", f"{source_text(p)}: no {'' if masks_gaps(p) else 'gap-free '}span (gaps over "
                          f"{ends} end one) lasts steps x dt_s = {p.steps} x {p.dt_s:g} s")
    states, first, valid = np.concatenate(parts), np.concatenate(boundary), np.concatenate(recorded)
    # a maneuver is seen on the steps the track has: the straight line across a gap is no evidence
    maneuvering = _runs_at_least((maneuver_size(states, p.maneuver_measure) >= maneuver_threshold(p)) & valid,
                                 first, p.min_maneuver_steps)
    z = np.concatenate(measured) if measured else None
    if z is not None:                       # a step without a measurement is missing, as one in a gap
        valid = valid & ~np.isnan(z[:, 0])
    onsets, quiet = _segment_starts(maneuvering, first, valid, p.steps, p.onset_step)
    return Bank(pos=states[:, 0], vel=states[:, 1], acc=states[:, 2], maneuvering=maneuvering,
                onsets=onsets, quiet=quiet, spans=len(parts), valid=valid, z=z, notes=notes)


def _segment_starts(maneuvering: np.ndarray, first: np.ndarray, valid: np.ndarray, K: int, onset: int):
    """First steps of the K-step segments inside one span that start at a recorded step:
    those whose steps before ``onset`` are quiet and whose step ``onset`` maneuvers (so
    was recorded), and those quiet throughout."""
    M = len(maneuvering)
    span_id = np.cumsum(first)
    s = np.arange(max(M - K + 1, 0))
    inside = (span_id[s] == span_id[s + K - 1]) & valid[s]
    busy = np.r_[0, np.cumsum(maneuvering)]                       # maneuvering steps before each index
    quiet_before = busy[s + onset] - busy[s] == 0
    quiet_all = busy[s + K] - busy[s] == 0
    return s[inside & quiet_before & maneuvering[s + onset]], s[inside & quiet_all]


def masks_gaps(p) -> bool:
    """Whether config ``p`` keeps the gaps over ``max_gap_s`` (up to ``masked_gap_s``) in a
    span, their steps missing."""
    return p.masked_gap_s > 0.0


def replays(p) -> bool:
    """Whether config ``p`` replays the file's recorded measurements."""
    return p.measurements == "recorded"


def is_ragged(p) -> bool:
    """Whether the trials of config ``p`` may miss steps: masked gaps, lengths under ``steps``,
    or replayed measurements (a step may have none)."""
    return masks_gaps(p) or 0 < p.min_steps < p.steps or replays(p)


def source_text(p) -> str:
    return p.path or "traffic samples " + ", ".join(p.traffic_samples)


def load_tracks(p) -> tuple[pd.DataFrame, tuple[str, ...]]:
    """The config's tracks (track, time_s, east, north), checked (:func:`checked_tracks`),
    and what reading them converted (:func:`read_file`'s note)."""
    if p.path:
        table, note = read_file(p.path)
        return checked_tracks(table, p.path, replays(p)), (note,) if note else ()
    return pd.concat([checked_tracks(read_sample(name), f"traffic sample {name}", replays(p))
                      for name in p.traffic_samples], ignore_index=True), ()


@functools.lru_cache(maxsize=8)
def bank_of(p) -> Bank:
    """:func:`build_bank` once per config and process: a worker reads the file once for
    all its units and trials (params are frozen, hence hashable)."""
    return build_bank(p)
