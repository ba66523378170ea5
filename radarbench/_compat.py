"""The compatibility path of the names the distribution installed before 0.2: ``bench``,
``methods``, ``models`` and ``scenarios`` (docs/architecture.md, 'Layout').

An import of an old name (``import bench.core``, ``from models.kalman import KalmanFilter``)
is answered by a finder at the front of :data:`sys.meta_path` with the very module object of
the new name (``radarbench.bench.core``): one module, one registry, whichever name a
plugin spells, and a :class:`OldImportName` warning naming the new import. The finder is
installed when :mod:`radarbench` is imported, which every route by which the harness loads
a plugin does first (the ``bench`` command, discovery of entry points, the workers), rather
than by a ``.pth`` file, which would run in every Python process of the environment and add
a second top-level entry to site-packages. A plugin's own script that imports an old name
before anything imported ``radarbench`` must ``import radarbench`` first (or, better, use
the new names). The path is kept for one release.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings

#: the old top-level names, each now ``radarbench.<name>``
OLD_NAMES = ("bench", "methods", "models", "scenarios")
NEW_PACKAGE = "radarbench"


class OldImportName(DeprecationWarning):
    """An import of a name the distribution no longer installs at the top level."""


def new_name(old: str) -> str | None:
    """``models.kalman`` -> ``radarbench.models.kalman``; None for a name not of ours."""
    return f"{NEW_PACKAGE}.{old}" if old.split(".")[0] in OLD_NAMES else None


class _AliasLoader(importlib.abc.Loader):
    """Loads an old name as the module of its new name (imported once, never executed again)."""

    def __init__(self, module):
        self.module, self.spec = module, module.__spec__

    def create_module(self, spec):
        return self.module

    def exec_module(self, module):
        module.__spec__ = self.spec     # the import system wrote the old name's spec over it

    def get_code(self, fullname):
        """``python -m bench`` runs ``radarbench.bench.__main__``'s code."""
        return self.spec.loader.get_code(self.spec.name)


class _AliasFinder(importlib.abc.MetaPathFinder):
    def find_spec(self, fullname, path=None, target=None):
        new = new_name(fullname)
        if new is None:
            return None
        module = importlib.import_module(new)
        _warn(fullname, new)
        return importlib.machinery.ModuleSpec(fullname, _AliasLoader(module), origin=getattr(module, "__file__", None),
                                              is_package=hasattr(module, "__path__"))


def _warn(old: str, new: str) -> None:
    warnings.warn(f"'{old}' is deprecated: import '{new}' (radar-maneuver-bench installs one "
                  f"top-level package, radarbench; the old names go in the next release)",
                  OldImportName, stacklevel=_importer_level())


def replace_old_package(old: str) -> None:
    """Called by a folder's ``__init__.py`` run under its old name (a checkout on sys.path,
    imported before :mod:`radarbench`): the import returns the new package instead (the import
    system reads the module back from :data:`sys.modules`), and the finder takes the submodules."""
    new = new_name(old)
    sys.modules[old] = importlib.import_module(new)
    _warn(old, new)


def _importer_level() -> int:
    """The stack level, for :func:`warnings.warn` called by :func:`_warn`, of the module that
    wrote the import: past this file's frames; the import system's own frames are skipped by
    :mod:`warnings` itself, so they are not counted."""
    frame, level = sys._getframe(1), 1
    while True:
        frame = frame.f_back
        while frame is not None and _import_system(frame):
            frame = frame.f_back
        if frame is None:
            return level
        level += 1
        if frame.f_code.co_filename != __file__:
            return level


def _import_system(frame) -> bool:
    """A frame :mod:`warnings` skips when it counts ``stacklevel`` (importlib's bootstrap)."""
    filename = frame.f_code.co_filename
    return "importlib" in filename and "_bootstrap" in filename


def install() -> None:
    """Put the finder first on :data:`sys.meta_path` (once): before the path finder, which
    in a checkout would otherwise import ``bench/`` a second time under its old name. Shows
    each old import once per place (the default hides a DeprecationWarning outside
    ``__main__``) unless the user chose warning filters (``-W``, ``PYTHONWARNINGS``)."""
    if any(isinstance(finder, _AliasFinder) for finder in sys.meta_path):
        return
    sys.meta_path.insert(0, _AliasFinder())
    if not sys.warnoptions:
        warnings.filterwarnings("default", category=OldImportName)
