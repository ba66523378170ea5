"""A third-party tracking scenario written from outside the repository: a planar
constant-velocity target whose trials may differ in length and have gaps (a
ragged batch, ``Scene.valid_steps``). It declares that it provides the
``kinematic-model`` capability, and, for a ragged config, requires
``valid-step-masks``; nothing in bench/ or methods/ names it.

:func:`load` writes the module into a temporary folder and imports it, as a
plugin package would be (the tests register the class themselves); :func:`install`
writes it as an installed distribution with its entry point."""

import importlib
import os
import sys
import textwrap
from pathlib import Path

SOURCE = '''
"""A planar CV target, measured in Gaussian noise; trials of random lengths with random gaps."""
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from radarbench.bench.core import TRACKING, Batch, Scenario
from radarbench.bench.params import param
from radarbench.bench.tasks.tracking import TrackingScene
from radarbench.models.kinematics import KinematicModel, position_index, state_labels


class CvReplay(Scenario):
    """Planar constant-velocity target; optionally ragged (random lengths and gaps)."""

    name = "cv-replay"
    tasks = (TRACKING,)
    provides = frozenset({"kinematic-model"})
    small_params: ClassVar[dict] = {"steps": 30}

    @dataclass(frozen=True)
    class Params:
        steps: int = param(40, "steps K of the longest trial", ge=2, le=10_000, why="a short test scene")
        min_steps: int = param(0, "steps of the shortest trial; 0: every trial has K", ge=0, le=10_000,
                               why="at most the longest")
        gap_probability: float = param(0.0, "probability that a step after the first is missing", ge=0.0,
                                       le=0.9, why="a probability; some steps are left")

    def requires(self, params):
        ragged = 0 < params.min_steps < params.steps or params.gap_probability > 0
        return frozenset({"valid-step-masks"}) if ragged else frozenset()

    def generate(self, params, snr_db, n, rng) -> Batch:
        K, dt = params.steps, 1.0
        noise = 10.0 * 10 ** (-(0.0 if snr_db is None else snr_db) / 20)
        t = dt * np.arange(K)
        start = 50.0 * rng.standard_normal(2)                    # (n, 2) m
        speed = 20.0 * rng.standard_normal(2)                   # (n, 2) m/s
        pos = start[:, None, :] + speed[:, None, :] * t[None, :, None]
        truth = np.zeros((n, K, 6))
        truth[..., [0, 3]], truth[..., [1, 4]] = pos, speed[:, None, :]
        z = pos + noise * rng.standard_normal((K, 2))
        valid = None
        if self.requires(params):
            low = params.min_steps or K
            length = low + np.floor(rng.uniform(1)[:, 0] * (K - low + 1)).astype(int)
            valid = (np.arange(K)[None, :] < length[:, None]) & (rng.uniform(K) >= params.gap_probability)
            valid[:, 0] = True
            z = np.where(valid[..., None], z, np.nan)
        model = KinematicModel(dt_s=dt, noise_std_m=float(noise), dims=2, x0=np.zeros(6),
                               P0=np.diag([1e4, 1e3, 1.0] * 2))
        scene = TrackingScene(model=model, state_labels=state_labels(2), position_index=position_index(2),
                              divergence_bound_m=1e4, valid_steps=valid)
        return Batch(t=t, truth=truth, z=z, scene=scene, trials=rng.trials)
'''


def load(folder: Path):
    """The scenario class, from a module written into ``folder`` and imported from there."""
    (folder / "cv_replay_plugin.py").write_text(textwrap.dedent(SOURCE))
    sys.path.insert(0, str(folder))
    try:
        sys.modules.pop("cv_replay_plugin", None)
        return importlib.import_module("cv_replay_plugin").CvReplay
    finally:
        sys.path.remove(str(folder))


def install(site: Path) -> dict:
    """The module as an installed distribution under ``site`` (its entry point in
    ``bench.scenarios``, what ``pip install`` leaves behind); returns an environment
    whose PYTHONPATH holds it."""
    (site / "benchreplay").mkdir(parents=True)
    (site / "benchreplay" / "__init__.py").write_text("")
    (site / "benchreplay" / "scenario.py").write_text(textwrap.dedent(SOURCE))
    info = site / "benchreplay-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: benchreplay\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[bench.scenarios]\ncv-replay = benchreplay.scenario:CvReplay\n")
    return dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), *filter(None, [os.environ.get("PYTHONPATH")])]))
