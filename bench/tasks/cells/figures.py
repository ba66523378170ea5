"""Figures of the cell-detection report: Pd vs SNR per clutter region, ROC per
region, one RD map with each detector's detections (matplotlib, via
:mod:`bench.figures`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from radarbench.bench.figures import STYLES, _legend_outside, _save, cached, plt
from radarbench.bench.recording.record import TrialRecord
from radarbench.bench.tasks.cells.metrics import ideal_pd

_REGION_COLORS = ["0.55", "tab:blue", "tab:orange", "tab:green", "tab:purple"]


def _panels(count: int, width: float = 3.6, height: float = 3.2):
    cols = min(count, 3)
    rows = int(np.ceil(count / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(width * cols + 1.8, height * rows), squeeze=False)
    for ax in axes.flat[count:]:
        ax.set_visible(False)
    return fig, list(axes.flat[:count])


@cached
def pd_panels(scene: pd.DataFrame, groups: list[str], columns: list[str], pfa: float, swerling: int, path: Path,
              title: str) -> Path:
    """One panel per target group: Pd vs SNR per config with its 95% band,
    and the ideal known-noise detector's Pd (dashed black)."""
    fig, axes = _panels(len(groups))
    fine = np.linspace(scene.snr_db.min(), scene.snr_db.max(), 200)
    for ax, group, col in zip(axes, groups, columns):
        for i, (config, g) in enumerate(scene.groupby("config", sort=False)):
            g = g.sort_values("snr_db")
            ax.plot(g.snr_db, g[col], STYLES[i % len(STYLES)], color=f"C{i % 10}", ms=3, lw=1.3, mfc="none",
                    label=config)
            ax.fill_between(g.snr_db, g[f"{col}_low"], g[f"{col}_high"], color=f"C{i % 10}", alpha=0.15, lw=0)
        ax.plot(fine, ideal_pd(fine, pfa, swerling), "k--", lw=1, label="ideal (known noise)")
        ax.set(title=group, xlabel="SNR (dB)", ylabel="$P_D$", ylim=(-0.02, 1.02))
        ax.grid(alpha=0.3)
    _legend_outside(axes[-1])
    fig.suptitle(f"{title}: $P_D$ vs SNR per clutter region at per-cell $P_{{FA}}$ = {pfa:g} (95% bands)",
                 fontsize=10)
    fig.set_layout_engine("tight")
    return _save(fig, path)


@cached
def roc_panels(curves: dict, pfa: float, path: Path, title: str) -> Path:
    """One panel per target group: Pd against the per-cell Pfa on the null maps, per config."""
    groups = [g for g, c in curves.items() if c]
    fig, axes = _panels(len(groups))
    for ax, group in zip(axes, groups):
        for i, (config, (x, y)) in enumerate(curves[group].items()):
            keep = x > 0
            ax.plot(x[keep], y[keep], STYLES[i % len(STYLES)][1:] or "-", color=f"C{i % 10}", lw=1.3, label=config)
        ax.axvline(pfa, color="0.5", lw=0.8, ls=":")
        ax.set_xscale("log")
        ax.set(title=group, xlabel="per-cell $P_{FA}$ (null maps)", ylabel="$P_D$", ylim=(-0.02, 1.02))
        ax.grid(alpha=0.3, which="both")
    _legend_outside(axes[-1])
    fig.suptitle(f"{title} (dotted: requested $P_{{FA}}$)", fontsize=10)
    fig.set_layout_engine("tight")
    return _save(fig, path)


@cached
def map_detections(rec: TrialRecord, configs: list[str], path: Path, title: str) -> Path:
    """The RD map (dB) with the true targets, the clutter regions, and one
    panel per detector with its declared cells (range up, Doppler across)."""
    rd = rec.image("rd_map_db")
    R, D = rd.shape
    extent = (-D // 2 - 0.5, D - D // 2 - 0.5, -0.5, R - 0.5)
    targets = rec.arrays.get("target_cells", np.zeros((1, 0, 2)))[0]
    fig, axes = _panels(len(configs) + 2, width=4.2, height=2.6)

    def show(ax, image, name, **kw):
        ax.imshow(image, origin="lower", aspect="auto", extent=extent, interpolation="nearest", **kw)
        if targets.size:
            ax.scatter(targets[:, 1] - D // 2, targets[:, 0], s=40, facecolors="none", edgecolors="w", lw=1.2)
        ax.set(title=name, xlabel="Doppler cell", ylabel="range cell")

    lo, hi = np.nanpercentile(rd, [1, 99.9])
    show(axes[0], rd, "RD map (dB)", cmap="viridis", vmin=lo, vmax=hi)
    if "regions" in rec.arrays:
        from matplotlib.colors import ListedColormap
        names = rec.info.get("region_names", [])
        show(axes[1], rec.arrays["regions"][0], "regions: " + ", ".join(
            f"{n} ({c.replace('tab:', '')})" if c[0] != "0" else f"{n} (grey)"
            for n, c in zip(names, _REGION_COLORS)), cmap=ListedColormap(_REGION_COLORS[:len(names)]),
            vmin=-0.5, vmax=len(names) - 0.5)
        axes[1].title.set_fontsize(7)
    for i, (ax, config) in enumerate(zip(axes[2:], configs)):
        show(ax, rd, config, cmap="gray", vmin=lo, vmax=hi)
        cells = rec.methods[config].arrays.get("detections", np.zeros((1, 0, 2)))[0]
        if cells.size:
            ax.scatter(cells[:, 1] - D // 2, cells[:, 0], s=6, color=f"C{i % 10}")
        ax.set_title(f"{config}: {len(cells)} cells", fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.set_layout_engine("tight")
    return _save(fig, path)
