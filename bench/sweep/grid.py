"""Grid expansion and config labels of a sweep file (docs/architecture.md, 'Sweep files
and presets').

In ``params`` (and ``scenario_params``) a list value is a grid axis and the Cartesian
product of the axes is expanded, one config per combination (:func:`expand`). For a
parameter whose type is itself a list (e.g. AR coefficients), a list of lists is the axis.

A config's identity is a readable label in the style of benchopt: ``cumulant[window=32]``,
the registry name plus the parameters the sweep set (for scenarios, only the grid axes).
A label the user gives is refused where it would misstate the config
(:func:`label_problem`). Every label of a plan, given or generated, is in
:data:`LABEL_PATTERN`'s alphabet and reads back as its config's (:func:`named`): plan.toml
writes the method labels out and ``bench run plan.toml`` and ``bench report`` read them
back, so a parameter value a label cannot hold (markup, a path separator, a comma) is
refused when the sweep is read, naming it, never once the run has computed.
"""

from __future__ import annotations

import itertools
import math
import re
from typing import Any, Mapping

from radarbench.bench import registry
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import build_params, field_types, is_tuple_field, params_as_dict
from radarbench.bench.sweep.plan import ComponentConfig, label_value

#: the most configs one grid (or one sweep's list of methods or scenarios) may expand to
MAX_CONFIGS = 1000
#: config labels: readable like "cumulant-as-printed" or "glint[epsilon=0.05]", never path-like
#: nor markup
LABEL_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.,:=+\-\[\]() ]{0,199}\Z")
LABEL_ALPHABET = "letters, digits, spaces or '_.,:=+-[]()' (at most 200, no path separators)"


def _grid_axes(params_cls: type, values: Mapping[str, Any], field: str) -> list[list[tuple[str, Any]]]:
    """Each parameter as a list of (name, value) choices (a grid axis)."""
    axes = []
    for key, value in values.items():
        if not isinstance(key, str):
            raise ConfigError(field, f"parameter names must be strings, got {key!r}")
        try:
            tuple_field = is_tuple_field(params_cls, key)
        except KeyError:
            tuple_field = False  # unknown names are reported by build_params
        is_axis = isinstance(value, list) and (not tuple_field or (value and all(isinstance(v, list) for v in value)))
        if is_axis:
            if not value:
                raise ConfigError(f"{field}.{key}", "empty list: a grid axis needs at least one value")
            axes.append([(key, v) for v in value])
        else:
            axes.append([(key, value)])
    return axes


def expand(name: str, params_cls: type, values: Mapping[str, Any], field: str, *,
            identity: str = "explicit", base: str | None = None) -> list[ComponentConfig]:
    """One config per grid point. ``identity`` says which parameters name a config:
    ``"explicit"`` every parameter the sweep set (methods), ``"grid"`` only the
    grid axes (scenarios: a single scenario config is just its name)."""
    axes = _grid_axes(params_cls, values, field)
    size = math.prod(len(a) for a in axes) if axes else 1
    if size > MAX_CONFIGS:
        raise ConfigError(field, f"grid of {size} configs; at most {MAX_CONFIGS}")
    configs = []
    for combo in itertools.product(*axes) if axes else [()]:
        try:
            params = build_params(params_cls, dict(combo), base)
        except ConfigError as err:
            raise err.within(field) from None
        named = [k for (k, _), axis in zip(combo, axes) if identity == "explicit" or len(axis) > 1]
        inner = ",".join(f"{k}={label_value(params, k)}" for k in named)
        configs.append(ComponentConfig(name, params, f"{name}[{inner}]" if inner else name, inner))
    return configs


def split_top_level(text: str) -> list[str]:
    """``text`` split at the commas outside parentheses and brackets (tuple values are
    "(a,b)"; a value naming a component with its parameters is "name[k=v,...]")."""
    parts, depth, start = [], 0, 0
    for i, c in enumerate(text):
        depth += (c in "([") - (c in ")]")
        if c == "," and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    return parts + [text[start:]]


def label_problem(name: str, label: str, params: Any, *, bare_means_defaults: bool) -> str | None:
    """Why a user's ``label`` for a config of component ``name`` with ``params``
    would misstate it (None if it does not): a label cannot look like another
    config's. The generated labels are ``name`` and ``name[k=v,...]``, so a
    label that is another component's name, or ``other[...]``, is refused; one
    of the form ``name[k=v,...]`` must say the config's own values (as the
    generated label would write them); a bare ``name`` (for a method, whose
    generated label lists every parameter the sweep set) only the defaults."""
    others = (set(registry.methods()) | set(registry.scenarios())) - {name}
    match = re.fullmatch(r"([A-Za-z0-9][A-Za-z0-9_.:\-]*)\[(.*)\]", label, re.DOTALL)
    if match is None:
        if label in others:
            return f"{label!r} is the label of a {label} config; this is a {name} config"
        if label == name and bare_means_defaults and params != type(params)():
            changed = [k for k, v in params_as_dict(params).items() if v != params_as_dict(type(params)())[k]]
            return (f"{label!r} is the label of the default {name} config, but this one sets "
                    f"{', '.join(changed)}; name it otherwise (or {name}[...] with its values)")
        return None
    owner, inner = match.groups()
    if owner != name:
        return f"{label!r} looks like the label of a {owner} config; this is a {name} config" \
            if owner in others else None
    fields = field_types(type(params))
    for part in split_top_level(inner):         # free text ("dp-tbd[prewhiten]") says nothing checkable
        key, eq, text = (x.strip() for x in part.partition("="))
        if eq and key in fields:
            actual = label_value(params, key)
            if text != actual:
                return f"{label!r} says {key}={text}, but this config has {key}={actual}"[:300]
    return None


def named(c: ComponentConfig, label: Any, field: str, *, bare_means_defaults: bool) -> ComponentConfig:
    """``c`` named by the user's ``label`` (None: its generated one), once the label is
    checked as plan.toml's reader will check it (:data:`LABEL_PATTERN`,
    :func:`label_problem`): a user's label in ``field.label``; a generated one in the
    parameter whose value it cannot hold, whose config then needs a label of its own."""
    if label is None:
        problem = _label_check(c.name, c.label, c.params, bare_means_defaults)
        if problem:
            culprit = next((k for k in _keys_in(c) if _label_check(
                c.name, f"{c.name}[{k}={label_value(c.params, k)}]", c.params, False)), "")
            raise ConfigError(f"{field}.{culprit}" if culprit else field,
                              f"{problem}: name this config with a 'label' (one config per entry)"[:400])
        return c
    label_field = f"{field.removesuffix('.params')}.label"
    if not isinstance(label, str) or not LABEL_PATTERN.match(label):
        raise ConfigError(label_field, f"expected {LABEL_ALPHABET}, got {label!r}"[:200])
    problem = label_problem(c.name, label, c.params, bare_means_defaults=bare_means_defaults)
    if problem:
        raise ConfigError(label_field, problem)
    return ComponentConfig(c.name, c.params, label, params_text_of_label(c.name, label))


def _keys_in(c: ComponentConfig) -> list[str]:
    """The parameters a generated label writes (``k=`` at the start or after a comma)."""
    return [k for k in field_types(type(c.params)) if re.search(rf"(^|,){re.escape(k)}=", c.params_text)]


def _label_check(name: str, label: str, params: Any, bare_means_defaults: bool) -> str | None:
    """Why ``label`` cannot name the config (its alphabet, or :func:`label_problem`); None: it can."""
    if not LABEL_PATTERN.match(label):
        return f"its label {label!r} is not {LABEL_ALPHABET}"[:300]
    return label_problem(name, label, params, bare_means_defaults=bare_means_defaults)


def params_text_of_label(name: str, label: str) -> str:
    """``window=32`` from ``cumulant[window=32]``; a free-form label is its own text."""
    if label == name:
        return ""
    if label.startswith(f"{name}[") and label.endswith("]"):
        return label[len(name) + 1:-1]
    return label
