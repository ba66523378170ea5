"""radar-maneuver-bench's one import package (docs/architecture.md, 'Layout').

The repository keeps its folders at the top (``bench/``, ``methods/``, ``models/``,
``scenarios/``); this folder holds a relative link to each (``bench -> ../bench``), so they
are :mod:`radarbench.bench`, :mod:`radarbench.methods`, :mod:`radarbench.models` and
:mod:`radarbench.scenarios` on disk, as static tools read them, and the distribution adds
no generic top-level name such as ``models`` to an environment. The package's path is
this folder's real one, whichever link led here (``src/radarbench``, the editable
install's): one file per module, so numba's cache and the tracebacks name one path.

Importing this package installs the compatibility path of the old names
(:mod:`radarbench._compat`): ``import bench.core`` or ``from models.kalman import ...``
in an outside plugin still works, with a deprecation warning naming the new import.

:func:`load_run` (a run's results as tidy pandas frames, :class:`Run`) comes from
:mod:`radarbench.bench.results.tidy`, imported on first use: every plugin imports this package,
and pandas is not imported for it.
"""

from pathlib import Path
from typing import TYPE_CHECKING

from radarbench import _compat

if TYPE_CHECKING:   # the lent names as static tools read them (jedi, pyright); at run time, _EXPORTS
    from radarbench.bench.results.tidy import Run, load_run

#: the subpackages, each a folder of the repository
SUBPACKAGES = _compat.OLD_NAMES

_HERE = Path(__file__).resolve().parent
__path__[:] = [str(_HERE)]              # noqa: F821 - a package's __path__
if not (_HERE / "bench").is_dir():
    raise ImportError(f"{_HERE / 'bench'} is not a folder: this clone has its links (radarbench/bench -> ../bench, "
                      "docs/architecture.md, 'Import names') as plain files; clone again with symbolic links "
                      "(git config --global core.symlinks true; on Windows, with Developer Mode on)")

_compat.install()


#: the names this package lends from its subpackages, imported when first used (the same
#: names as the TYPE_CHECKING import above: tests/test_static_imports.py compares them)
_EXPORTS = {"load_run": "radarbench.bench.results.tidy", "Run": "radarbench.bench.results.tidy"}


def __getattr__(name: str):
    """``radarbench.load_run`` / ``radarbench.Run``: imported on first use (PEP 562)."""
    if name in _EXPORTS:
        import importlib
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
