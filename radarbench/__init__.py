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
"""

from pathlib import Path

from radarbench import _compat

#: the subpackages, each a folder of the repository
SUBPACKAGES = _compat.OLD_NAMES

_HERE = Path(__file__).resolve().parent
if not (_HERE / "bench").is_dir():      # a checkout (or an editable install): the folders beside this one
    __path__.append(str(_HERE.parent))  # noqa: F821 - a package's __path__

_compat.install()
