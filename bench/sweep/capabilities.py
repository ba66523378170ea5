"""What a scene provides and what a method needs: the pairing of methods with
scenarios (docs/architecture.md, 'Capabilities').

A method runs on a scenario config when it performs one of the scenario's tasks,
every capability it ``needs`` is one the scenario ``provides``, and it handles
every capability the scenario config ``requires`` of its methods (a ragged batch:
trials of different lengths or with gaps). A capability names what a method reads
from a scene *beyond* what its task's scene type guarantees (every multi-target
scene has plots with Pd and clutter, every cell-detection scene a map): a method
that needs nothing runs on every scenario of its task, a scenario that provides
nothing gets those methods, as before capabilities existed.

The names below are the built-in vocabulary; a plugin may use its own names (they
are shown as written). The harness never names a method, a scenario or a task.
"""

from __future__ import annotations

#: the built-in capability names and what each means, in one phrase
CAPABILITIES: dict[str, str] = {
    "kinematic-model": "position measurements (a range or planar x/y) with a known noise std and a fixed-step "
                       "kinematic model: the tracking scene's model is a models.kinematics.KinematicModel",
    "glint-model": "spherical measurements under glint noise with known dynamics: the tracking scene's model "
                   "is a models.glint.GlintModel",
    "reference-filter": "a reference linear Kalman filter whose innovations are tested: the detection scene's "
                        "reference_filter, a models.kalman.LinearGaussianFilter",
    "valid-step-masks": "ragged batches: trials of different lengths or with gaps (Scene.valid_steps), the "
                        "missing steps skipped",
}

#: what a scenario config whose trials may differ in length or have gaps requires of a method
VALID_STEP_MASKS = "valid-step-masks"


def phrase(names) -> str:
    """The capabilities ``names`` in words: 'name (meaning)', joined by ' and '."""
    return " and ".join(f"{n} ({CAPABILITIES[n]})" if n in CAPABILITIES else n for n in sorted(names))


def _requires(scenario_cls, scenario_params) -> frozenset[str]:
    params = scenario_cls.default_params() if scenario_params is None else scenario_params
    return frozenset(scenario_cls().requires(params))


def missing(method_cls, scenario_cls, scenario_params=None) -> str | None:
    """Why ``method_cls`` cannot run on a config of ``scenario_cls`` with
    ``scenario_params`` (None: its defaults), in one line naming what is missing;
    None when it can. A method of another task is refused too."""
    method, scenario = repr(method_cls.name), repr(scenario_cls.name)
    if method_cls.task not in scenario_cls.tasks:
        return f"{method} performs {method_cls.task}; {scenario} serves {', '.join(scenario_cls.tasks)}"
    lacking = frozenset(method_cls.needs) - frozenset(scenario_cls.provides)
    if lacking:
        offered = ", ".join(sorted(scenario_cls.provides)) or "nothing beyond its task's scene"
        return f"{method} needs {phrase(lacking)}; {scenario} provides {offered}"
    unhandled = _requires(scenario_cls, scenario_params) - frozenset(method_cls.handles)
    if unhandled:
        return f"{scenario} with these params requires {phrase(unhandled)}, which {method} does not handle"
    return None


def check_batch(method_cls, batch) -> None:
    """A ValueError unless ``method_cls`` handles what ``batch`` holds: a ragged batch
    (``scene.valid_steps`` set) from a scenario config that did not declare it in
    ``requires`` reaches only a method that handles ``valid-step-masks`` (the unit's
    failure for the others, not NaN estimates)."""
    if batch.scene.valid_steps is not None and VALID_STEP_MASKS not in method_cls.handles:
        raise ValueError(f"the batch is ragged (scene.valid_steps is set) and {method_cls.name!r} does not handle "
                         f"{VALID_STEP_MASKS}; the scenario's requires(params) should say so, so the sweep "
                         f"refuses the pair")


def fits(method_cls, scenario_cls, scenario_params=None) -> bool:
    """Whether ``method_cls`` runs on a config of ``scenario_cls`` (:func:`missing` is None)."""
    return missing(method_cls, scenario_cls, scenario_params) is None
