"""Report figures (matplotlib, Agg backend): PNGs readable on GitHub.

Each figure function builds its figure and hands it to :func:`_save`. Inside
:func:`rendering_in` a pool's processes render them (a figure pickles in a few
milliseconds and renders in a few hundred: the drawing is the cost) while the report
goes on; the PNGs are written, each whole, when the block ends. Inside
:func:`reusing`, a figure function marked :func:`cached` is not even built when the
same figure was drawn before from the same inputs and code (:mod:`bench.results.figure_cache`).
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import inspect
import io
import pickle
from concurrent.futures import BrokenExecutor
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib import ticker  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from radarbench.bench.results.figure_cache import reuse_in_effect  # noqa: E402
from radarbench.bench.results.tables import identical_curves  # noqa: E402

DPI = 110
#: zlib level of the PNGs: 1 encodes several times faster than Pillow's default 6, for files a little larger
PNG_COMPRESS_LEVEL = 1

#: the figures of the :func:`rendering_in` block in progress: [(path, pickled figure, future of its PNG or None)]
_pending: contextvars.ContextVar[list | None] = contextvars.ContextVar("pending_figures", default=None)
_pool: contextvars.ContextVar = contextvars.ContextVar("figure_pool", default=None)
#: the key of the figure a :func:`cached` function is drawing (None: not known)
_key: contextvars.ContextVar = contextvars.ContextVar("figure_key", default=None)


def cached(fn):
    """Mark the figure function ``fn`` (whose argument ``path`` names its PNG) as drawn
    from its arguments alone: inside :func:`reusing`, a figure drawn before from equal
    arguments by the same code is reused, not built (:mod:`bench.results.figure_cache`)."""
    signature = inspect.signature(fn)

    @functools.wraps(fn)
    def figure(*args, **kwargs):
        reuse = reuse_in_effect()
        if reuse is None:
            return fn(*args, **kwargs)
        bound = signature.bind(*args, **kwargs)
        bound.apply_defaults()
        arguments = dict(bound.arguments)
        path = Path(arguments.pop("path"))
        key = reuse.key(fn, arguments)
        if key is not None and reuse.reuse(path, key):
            return path
        token = _key.set(key)
        try:
            return fn(*args, **kwargs)
        finally:
            _key.reset(token)
    return figure


def _write(path: Path, data: bytes, key: str | None) -> None:
    """The PNG ``data`` of the figure ``key`` to ``path`` (inside :func:`reusing`: only if
    its bytes changed, counted as drawn)."""
    from radarbench.bench.results import runfolder
    reuse = reuse_in_effect()
    if reuse is None:
        runfolder.write_bytes(path, data)
    else:
        reuse.written(path, key, data)


def png(fig) -> bytes:
    """``fig`` rendered as a PNG (then closed)."""
    buf = io.BytesIO()
    try:
        fig.savefig(buf, format="png", dpi=DPI, bbox_inches="tight", pil_kwargs={"compress_level": PNG_COMPRESS_LEVEL})
    finally:
        plt.close(fig)
    return buf.getvalue()


def _png_of_pickled(data: bytes) -> bytes:
    return png(pickle.loads(data))


def _save(fig, path: Path) -> Path:
    """Write ``fig`` to ``path`` whole (:func:`bench.results.runfolder.atomic_output`), now or,
    inside :func:`rendering_in`, once the block ends."""
    from radarbench.bench.results import runfolder
    pending = _pending.get()
    try:
        runfolder.folder_for(path.parent)
        if pending is None:
            _write(path, png(fig), _key.get())
        else:
            # pickled now, in this thread: the pool's feeder thread would pickle it later, after the close below
            data = pickle.dumps(fig)
            pending.append((path, data, submitted(_pool.get(), _png_of_pickled, data), _key.get()))
    finally:
        plt.close(fig)
    return path


def submitted(pool, fn, *args):
    """``pool.submit(fn, *args)``, or None if the pool cannot take it (it broke: a process
    died or could not start): :func:`result_of` then calls ``fn`` here."""
    try:
        return pool.submit(fn, *args)
    except (BrokenExecutor, RuntimeError, OSError) as exc:
        _say_broken(exc)
        return None


def result_of(job, fn, *args):
    """The result of ``job`` (:func:`submitted`); if the pool broke, ``fn(*args)`` in this
    process, said once on stderr: a dead pool costs speed, never an output. An error of
    ``fn`` itself is raised as it would be here."""
    if job is not None:
        try:
            return job.result()
        except BrokenExecutor as exc:
            _say_broken(exc)
    return fn(*args)


_broken_said = False


def _say_broken(exc: BaseException) -> None:
    global _broken_said
    if not _broken_said:
        _broken_said = True
        from radarbench.bench.run.progress import say
        say(f"the figure processes stopped ({exc}); drawing the rest here")


@contextlib.contextmanager
def rendering_in(pool):
    """Within the block, :func:`_save` hands each figure to ``pool`` (a
    :class:`concurrent.futures.Executor`; None: draw in this process, as outside the
    block) and returns at once; the PNGs are written when the block ends without an
    error (on one, none is written). A pool that breaks costs speed only
    (:func:`result_of`)."""
    if pool is None:
        yield
        return
    pending: list = []
    tokens = _pending.set(pending), _pool.set(pool)
    try:
        yield
    except BaseException:
        for _, _, job, _ in pending:
            if job is not None:
                job.cancel()
        raise
    finally:
        _pending.reset(tokens[0])
        _pool.reset(tokens[1])
    for path, data, job, key in pending:
        _write(path, result_of(job, _png_of_pickled, data), key)


def _legend_outside(ax) -> None:
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)


STYLES = ("o-", "s--", "^-.", "D:", "v-", "P--", "X-.", "*:")


def _curves(summary: pd.DataFrame, x: str = "snr_db", column: str | None = None):
    """(colour, marker/line style, label, rows sorted by ``x``) per config; styles differ so
    equal curves stay visible, and a config whose ``column`` equals an earlier one's at
    every level says so in its label (:func:`bench.results.tables.identical_curves`)."""
    same = identical_curves(summary, column) if column and x == "snr_db" else {}
    for i, (config, g) in enumerate(summary.groupby("config", sort=False)):
        label = config if config not in same else f"{config} (identical to {same[config]})"
        yield f"C{i % 10}", STYLES[i % len(STYLES)], label, g.sort_values(x)


@cached
def pd_vs_snr(summary: pd.DataFrame, path: Path, pfa: float, title: str,
              chance: dict[str, float] | None = None, column: str = "pd",
              ylabel: str = "probability of detection $P_D$", condition: str | None = None) -> Path:
    """Pd (the summary's ``column``, default ``pd``) against SNR per method config, with
    its 95% band (``column`` + ``_low``/``_high``) and, dotted, the chance level of
    that Pd measured on null trials (``chance``: config -> level); ``condition`` names
    how the thresholds were set (default: the per-step Pfa)."""
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    for color, style, label, g in _curves(summary, column=column):
        ax.plot(g.snr_db, g[column], style, color=color, ms=4, lw=1.5, label=label, mfc="none")
        ax.fill_between(g.snr_db, g[f"{column}_low"], g[f"{column}_high"], color=color, alpha=0.18, lw=0)
        level = (chance or {}).get(g.config.iloc[0], np.nan)
        if np.isfinite(level):
            ax.axhline(level, color=color, lw=1, ls=":", alpha=0.8)
    ax.axhline(0.5, color="0.6", lw=0.8, ls=":")
    ax.set(xlabel="SNR (dB)", ylabel=ylabel, ylim=(-0.02, 1.02),
           title=f"{title}: $P_D$ vs SNR {condition or f'at $P_{{FA}}$ = {pfa:g}'} (95% bands)")
    ax.grid(alpha=0.3)
    _legend_outside(ax)
    return _save(fig, path)


@cached
def delay_vs_snr(summary: pd.DataFrame, path: Path, title: str) -> Path:
    """Mean detection delay of detected trials, with its bootstrap band."""
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    for color, style, label, g in _curves(summary, column="delay_mean"):
        ok = g.delay_mean.notna()
        ax.plot(g.snr_db[ok], g.delay_mean[ok], style, color=color, ms=4, lw=1.5, label=label, mfc="none")
        ax.fill_between(g.snr_db[ok], g.delay_low[ok], g.delay_high[ok], color=color, alpha=0.18, lw=0)
        ax.plot(g.snr_db[ok], g.delay_median[ok], "_", color=color, ms=9, mew=1.5)
    ax.set(xlabel="SNR (dB)", ylabel="delay of detected trials (steps)",
           title=f"{title}: mean detection delay (95% bootstrap bands), median as –")
    ax.grid(alpha=0.3)
    _legend_outside(ax)
    return _save(fig, path)


@cached
def roc(curves: dict[str, tuple[np.ndarray, np.ndarray]], path: Path, snr_db: float, pfa: float,
        title: str) -> Path:
    """Pd against per-step Pfa at one SNR, per method config (log Pfa axis)."""
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    for i, (label, (x, y)) in enumerate(curves.items()):
        ax.plot(x, y, STYLES[i % len(STYLES)][1:] or "-", color=f"C{i % 10}", lw=1.5, label=label)
    ax.axvline(pfa, color="0.5", lw=0.8, ls=":")
    ax.set_xscale("log")
    ax.set(xlabel="per-step $P_{FA}$ (null trials)", ylabel="$P_D$", ylim=(-0.02, 1.02),
           title=f"{title}: ROC at {snr_db:.1f} dB (dotted: requested $P_{{FA}}$)")
    ax.grid(alpha=0.3, which="both")
    _legend_outside(ax)
    return _save(fig, path)


class PlainLogLabels(ticker.Formatter):
    """Tick labels of a log axis as plain numbers ("0.1", "10"; with ``minor``, 2 and 5 between
    decades when the axis spans less than two), not matplotlib's default mathtext ("10^1"): the
    parser's start-up is most of a report's drawing when the runtime's figure, drawn anew by
    every run, is its only one."""

    def __init__(self, minor: bool = False):
        self.minor = minor

    def __call__(self, value, pos=None) -> str:
        if not self.minor:
            return f"{value:g}"
        low, high = sorted(self.axis.get_view_interval())
        mantissa = round(value / 10 ** np.floor(np.log10(value)), 6)
        return f"{value:g}" if low > 0 and high / low < 100 and mantissa in (2.0, 5.0) else ""


@cached
def runtime(per_method: pd.DataFrame, path: Path) -> Path:
    """CPU seconds per trial per method config (log scale)."""
    fig, ax = plt.subplots(figsize=(7.5, 0.5 + 0.45 * len(per_method)))
    y = np.arange(len(per_method))
    ax.barh(y, per_method.seconds_per_trial * 1e3, color=[f"C{i % 10}" for i in y])
    ax.set_yticks(y, per_method.config, fontsize=8)
    ax.invert_yaxis()
    ax.set_xscale("log")
    ax.xaxis.set_major_formatter(PlainLogLabels())
    ax.xaxis.set_minor_formatter(PlainLogLabels(minor=True))
    ax.set(xlabel="CPU milliseconds per trial", title="runtime per method config")
    ax.grid(alpha=0.3, axis="x")
    return _save(fig, path)


@cached
def trial_timeline(t: np.ndarray, series: dict[str, tuple[np.ndarray, float, np.ndarray]], path: Path,
                   title: str) -> Path:
    """One trial's statistic and threshold per method over time (the paper's single-run figure);
    ``series``: label -> (statistic (K,), threshold, alarms (K,) bool)."""
    fig, axes = plt.subplots(len(series), 1, figsize=(7.5, 1.9 * len(series) + 0.6), sharex=True,
                             squeeze=False)
    for ax, (i, (label, (statistic, threshold, alarms))) in zip(axes[:, 0], enumerate(series.items())):
        color = f"C{i % 10}"
        ax.plot(t, statistic, color=color, lw=1.2, label=label)
        ax.axhline(threshold, color="k", lw=0.9, ls="--", label="threshold")
        hit = np.asarray(alarms, bool)
        ax.plot(t[hit], statistic[hit], "v", color="crimson", ms=4, label="alarm")
        ax.set_yscale("symlog", linthresh=max(threshold, 1e-6))
        ax.legend(fontsize=7, loc="upper left")
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time (s)")
    fig.suptitle(title, fontsize=10)
    return _save(fig, path)


@cached
def rmse_per_step(curves: dict[str, tuple[np.ndarray, np.ndarray]], path: Path, title: str,
                  xlabel: str = "frame", ylabel: str = "position RMSE (m)",
                  bound: tuple[np.ndarray, np.ndarray] | None = None) -> Path:
    """Per-step RMSE curves, one per label; ``bound`` (x, y): a lower bound on them (the
    posterior Cramér-Rao bound), drawn as a black dashed line."""
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    for i, (label, (x, y)) in enumerate(curves.items()):
        ax.plot(x, y, STYLES[i % len(STYLES)], color=f"C{i % 10}", ms=3.5, lw=1.4, label=label, mfc="none")
    if bound is not None:
        ax.plot(*bound, "--", color="black", lw=1.2, label="PCRB (bound)")
    ax.set(xlabel=xlabel, ylabel=ylabel, title=title)
    ax.grid(alpha=0.3)
    _legend_outside(ax)
    return _save(fig, path)


def metric_vs_snr(summary: pd.DataFrame, path: Path, title: str, column: str = "rmse_mean",
                  ylabel: str = "time-averaged position RMSE (m)", log: bool = False) -> Path:
    """A summary metric against SNR per config, with its interval band when present."""
    return metric_vs(summary, "snr_db", path, title, column, ylabel, "SNR (dB)", log=log)


@cached
def metric_vs(summary: pd.DataFrame, x: str, path: Path, title: str, column: str, ylabel: str, xlabel: str,
              log: bool = False, logx: bool = False) -> Path:
    """A summary metric against the summary column ``x`` per config, with its
    interval band (``*_low``, ``*_high`` beside ``*_mean``) when present."""
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    for color, style, label, g in _curves(summary, x, column):
        ok = g[column].notna()
        ax.plot(g[x][ok], g[column][ok], style, color=color, ms=4, lw=1.5, label=label, mfc="none")
        low, high = column.replace("_mean", "_low"), column.replace("_mean", "_high")
        if low in g and high in g:
            ax.fill_between(g[x][ok], g[low][ok], g[high][ok], color=color, alpha=0.18, lw=0)
    if log:
        ax.set_yscale("log")
    if logx:
        ax.set_xscale("log")
    ax.set(xlabel=xlabel, ylabel=ylabel, title=title)
    ax.grid(alpha=0.3, which="both")
    _legend_outside(ax)
    return _save(fig, path)


@cached
def grouped_bars(values: pd.DataFrame, low: pd.DataFrame, high: pd.DataFrame, path: Path, title: str,
                 ylabel: str, log: bool = False) -> Path:
    """Bars per (row = group, column = series) with interval whiskers."""
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    groups, series = list(values.index), list(values.columns)
    width = 0.8 / max(len(series), 1)
    x = np.arange(len(groups))
    for j, name in enumerate(series):
        v = values[name].to_numpy(float)
        err = np.vstack([v - low[name].to_numpy(float), high[name].to_numpy(float) - v])
        # a percentile-bootstrap interval of a nonlinear statistic (a time-averaged RMSE) may
        # exclude the estimate over few trials: the whisker then stops at the bar
        ax.bar(x + (j - (len(series) - 1) / 2) * width, v, width, yerr=np.clip(np.nan_to_num(err), 0, None), capsize=3,
               color=f"C{j % 10}", label=name)
    ax.set_xticks(x, groups, fontsize=8, rotation=15)
    if log:
        ax.set_yscale("log")
    ax.set(ylabel=ylabel, title=title)
    ax.grid(alpha=0.3, axis="y", which="both")
    _legend_outside(ax)
    return _save(fig, path)


@cached
def mean_estimates(t: np.ndarray, panels: dict[str, tuple[np.ndarray, dict[str, np.ndarray]]], path: Path,
                   title: str) -> Path:
    """Mean estimate across trials against the mean truth, per step: one panel
    per component (``panels[component] = (truth, {label: estimate})``)."""
    cols = 3 if len(panels) > 4 else min(2, len(panels))
    rows = -(-len(panels) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 2.6 * rows + 0.8), sharex=True, squeeze=False)
    for ax, (comp, (truth, estimates)) in zip(axes.ravel(), panels.items()):
        ax.plot(t, truth, "-", color="k", lw=2.2, label="truth (mean)")
        for i, (label, y) in enumerate(estimates.items()):
            ax.plot(t, y, STYLES[i % len(STYLES)][1:] or "-", color=f"C{i % 10}", lw=1.2, label=label)
        ax.set_title(comp, fontsize=9)
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[len(panels):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=min(4, len(labels)), fontsize=8, frameon=False)
    fig.suptitle(title, fontsize=10)
    fig.set_layout_engine("tight", rect=(0, 0.07, 1, 0.96))
    return _save(fig, path)


@cached
def trial_in_plane(truth_xy: np.ndarray, measurements_xy: np.ndarray | None, estimates: dict[str, np.ndarray],
                   maneuvering: np.ndarray | None, path: Path, title: str) -> Path:
    """One trial in the plane (metres, equal scales): the truth (its maneuvering steps
    thicker, the onset starred), the measurements, each tracker's estimate (K, 2)."""
    fig, ax = plt.subplots(figsize=(7.5, 6.0))
    if measurements_xy is not None:
        ax.plot(measurements_xy[:, 0], measurements_xy[:, 1], ".", color="0.6", ms=3, label="measurements")
    ax.plot(truth_xy[:, 0], truth_xy[:, 1], "-", color="k", lw=2.0, label="truth")
    if maneuvering is not None and np.any(maneuvering):
        inside = np.where(np.asarray(maneuvering, bool), 1.0, np.nan)
        ax.plot(truth_xy[:, 0] * inside, truth_xy[:, 1] * inside, "-", color="crimson", lw=4.0, alpha=0.5,
                label="truth, maneuvering")
        onset = int(np.argmax(maneuvering))
        ax.plot(*truth_xy[onset], "*", color="crimson", ms=12, label="first maneuvering step")
    for i, (label, xy) in enumerate(estimates.items()):
        ax.plot(xy[:, 0], xy[:, 1], STYLES[i % len(STYLES)][1:] or "-", color=f"C{i % 10}", lw=1.2, label=label)
    ax.plot(*truth_xy[0], "o", color="k", ms=6, mfc="none", label="start")
    ax.set(xlabel="x (m)", ylabel="y (m)", title=title)
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    _legend_outside(ax)
    return _save(fig, path)


@cached
def null_score_fits(fits: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, float, str]], path: Path,
                    pfa: float, title: str) -> Path:
    """Empirical survival function of the null scene scores (steps) against the
    fitted law's (dashed; ``fits``: label -> (scores, grid, survival on the grid,
    threshold used, the law's name)), with the threshold used (dotted)."""
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    for i, (label, (values, grid, fitted, used, law)) in enumerate(fits.items()):
        color = f"C{i % 10}"
        v = np.sort(values)
        survival = 1.0 - np.arange(v.size) / v.size
        ax.step(v, survival, where="post", color=color, lw=1.3, label=f"{label} (null scenes)")
        ax.plot(grid, fitted, "--", color=color, lw=1.2, label=f"{label} {law} fit")
        ax.axvline(used, color=color, ls=":", lw=1)
    ax.axhline(pfa, color="0.5", lw=0.8, ls=":")
    ax.set_yscale("log")
    ax.set_ylim(bottom=min(pfa / 3, 0.5 / max(len(v), 1)))
    ax.set(xlabel="scene score (largest merit at the last frame)", ylabel="P(score ≥ x) under the null",
           title=title)
    ax.grid(alpha=0.3, which="both")
    _legend_outside(ax)
    return _save(fig, path)
