"""radar-maneuver-bench's one import package (docs/architecture.md, 'Layout').

The repository keeps its folders at the top (``bench/``, ``methods/``, ``models/``,
``scenarios/``); the distribution installs them as :mod:`radarbench.bench`,
:mod:`radarbench.methods`, :mod:`radarbench.models` and :mod:`radarbench.scenarios`
(pyproject.toml's ``package-dir``), so it adds no generic top-level name such as
``models`` to an environment. In a checkout the four folders are the package's
subpackages through ``__path__`` (this folder's parent holds them).

Importing this package installs the compatibility path of the old names
(:mod:`radarbench._compat`): ``import bench.core`` or ``from models.kalman import ...``
in an outside plugin still works, with a deprecation warning naming the new import.

:func:`load_run` (a run's results as tidy pandas frames, :class:`Run`) comes from
:mod:`radarbench.bench.results.tidy`, imported on first use: every plugin imports this package,
and pandas is not imported for it.
"""

from pathlib import Path

from radarbench import _compat

#: the subpackages, each a folder of the repository
SUBPACKAGES = _compat.OLD_NAMES

_HERE = Path(__file__).resolve().parent
if not (_HERE / "bench").is_dir():      # a checkout (or an editable install): the folders beside this one
    __path__.append(str(_HERE.parent))  # noqa: F821 - a package's __path__

_compat.install()


#: the names this package lends from its subpackages, imported when first used
_LAZY = {"load_run": "radarbench.bench.results.tidy", "Run": "radarbench.bench.results.tidy"}


def __getattr__(name: str):
    """``radarbench.load_run`` / ``radarbench.Run``: imported on first use (PEP 562)."""
    if name in _LAZY:
        import importlib
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
