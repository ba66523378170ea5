"""The compatibility path of the names the distribution installed before 0.2: ``bench``,
``methods``, ``models`` and ``scenarios`` (docs/architecture.md, 'Import names').

An import of an old name (``import bench.core``, ``from models.kalman import KalmanFilter``)
is answered by a finder at the front of :data:`sys.meta_path` with the very module object of
the new name (``radarbench.bench.core``): one module, one registry, whichever name a
plugin spells, and one :class:`OldImportName` warning naming the new import (the old
packages an import passes through on its way, ``methods`` of ``methods.imm``, say nothing
of their own). A module that moved since is answered by its new home (:data:`MOVED`:
``methods.imm`` is ``radarbench.methods.kinematic.imm``), and so is a name the package
itself had before a later move (:data:`MOVED_SINCE_PACKAGE`:
``radarbench.models.cfar_halves``). Two old modules now share their name with their
family's folder (``methods.cfar``, ``methods.multitarget``): the old name gives the folder's
package, which then lends the names of the module that moved (:data:`MOVED`) to lookups
it cannot answer itself. An old name of a module that does not exist is one line naming
what its package holds.

The finder is installed when :mod:`radarbench` is imported, which every route by which the
harness loads a plugin does first (the ``bench`` command, discovery of entry points, the
workers), rather than by a ``.pth`` file, which would run in every Python process of the
environment and add a second top-level entry to site-packages. So a plugin's own script
(one the ``bench`` command does not run) must ``import radarbench`` before its first old
import (or, better, use the new names): without it, an installed distribution has no
top-level ``methods`` and the import fails with Python's own "No module named 'methods'".
The path is kept for one release.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import pkgutil
import sys
import warnings

#: the old top-level names, each now ``radarbench.<name>``
OLD_NAMES = ("bench", "methods", "models", "scenarios")
NEW_PACKAGE = "radarbench"

#: every module that moved since its old name was installed: old name -> its home now, both
#: under ``radarbench`` (a module moved twice maps to its last home). From the repository's
#: history (``git log -M --name-status``); tests/test_compat.py derives it again and compares.
MOVED = {
    # the tasks' modules, into one folder per task
    "bench.report_tbd": "bench.tasks.tbd.report",
    "bench.report_tracking": "bench.tasks.tracking.report",
    "bench.tasks.cells_draw": "bench.tasks.cells.draw",
    "bench.tasks.cells_figures": "bench.tasks.cells.figures",
    "bench.tasks.cells_metrics": "bench.tasks.cells.metrics",
    "bench.tasks.cells_report": "bench.tasks.cells.report",
    "bench.tasks.detection_metrics": "bench.tasks.detection.metrics",
    "bench.tasks.detection_report": "bench.tasks.detection.report",
    "bench.tasks.multitarget_metrics": "bench.tasks.multitarget.metrics",
    "bench.tasks.multitarget_recording": "bench.tasks.multitarget.draw",
    "bench.tasks.multitarget_report": "bench.tasks.multitarget.report",
    "bench.tasks.tbd_metrics": "bench.tasks.tbd.metrics",
    "bench.tasks.tbd_report": "bench.tasks.tbd.report",
    "bench.tasks.tracking_metrics": "bench.tasks.tracking.metrics",
    "bench.tasks.tracking_report": "bench.tasks.tracking.report",
    # shared maths, from the harness to models/
    "bench.glint_density": "models.glint",
    "bench.kalman": "models.kalman",
    # the methods, into one folder per family
    "methods.cfar": "methods.cfar.detectors",
    "methods._cfar_reference": "methods.cfar.reference",
    "methods.ekf": "methods.glint.ekf",
    "methods.viterbi": "methods.glint.viterbi",
    "methods._viterbi_paper1d": "methods.glint.viterbi_paper1d",
    "methods.ar_adaptive": "methods.kinematic.ar_adaptive",
    "methods._kinematic_base": "methods.kinematic.base",
    "methods.current_statistical": "methods.kinematic.current_statistical",
    "methods.imm": "methods.kinematic.imm",
    "methods.kinematic_kf": "methods.kinematic.kinematic_kf",
    "methods.vd_filter": "methods.kinematic.vd_filter",
    "methods._innovation_base": "methods.maneuver.base",
    "methods.cumulant": "methods.maneuver.cumulant",
    "methods.cusum": "methods.maneuver.cusum",
    "methods.glr": "methods.maneuver.glr",
    "methods.innovation": "methods.maneuver.innovation",
    "methods.wavelet": "methods.maneuver.wavelet",
    "methods._jpda": "methods.multitarget.jpda",
    "methods._mtt_kernels": "methods.multitarget.kernels",
    "methods.multitarget": "methods.multitarget.trackers",
    "methods.stonesoup_gmphd": "methods.multitarget.stonesoup_gmphd",
    "methods.stonesoup_mht": "methods.multitarget.stonesoup_mht",
    "methods.stonesoup_peer": "methods.multitarget.stonesoup_peer",
    "methods._track_management": "methods.multitarget.track_management",
    "methods._tbd_alongtrack": "methods.tbd.alongtrack",
    "methods.dp_tbd": "methods.tbd.dp_tbd",
    "methods._tbd_kernels": "methods.tbd.kernels",
    "methods._tbd_mf_kernels": "methods.tbd.mf_kernels",
    "methods._tbd_pf_kernels": "methods.tbd.pf_kernels",
    "methods.pf_tbd": "methods.tbd.pf_tbd",
    "methods._tbd_reference": "methods.tbd.reference",
    # the CFAR maths, into one folder
    "models.cfar_halves": "models.cfar.halves",
    "models.cfar_peaks": "models.cfar.peaks",
    "models.cfar_regression": "models.cfar.regression",
    "models.order_statistic": "models.cfar.order_statistic",
    # the harness's modules, into one folder per stage of the pipeline (or out to models/)
    "bench._forkserver": "bench.run._forkserver",
    "bench.baselines": "bench.report.baselines",
    "bench.capabilities": "bench.sweep.capabilities",
    "bench.claims": "bench.report.claims",
    "bench.config": "bench.sweep.config",
    "bench.docs": "bench.cli.docs",
    "bench.executors": "bench.run.executors",
    "bench.failures": "bench.results.failures",
    "bench.feasibility": "bench.sweep.feasibility",
    "bench.figure_cache": "bench.results.figure_cache",
    "bench.grid": "bench.sweep.grid",
    "bench.identity": "bench.run.identity",
    "bench.limits": "bench.run.limits",
    "bench.listing": "bench.sweep.listing",
    "bench.numba_cache": "bench.run.numba_cache",
    "bench.perf": "bench.cli.perf",
    "bench.plan": "bench.sweep.plan",
    "bench.processes": "bench.run.processes",
    "bench.progress": "bench.run.progress",
    "bench.provenance": "bench.results.provenance",
    "bench.quantities": "bench.report.quantities",
    "bench.results.results_cache": "bench.run.results_cache",
    "bench.results_cache": "bench.run.results_cache",
    "bench.reuse": "bench.run.reuse",
    "bench.rng": "bench.sweep.rng",
    "bench.runfolder": "bench.results.runfolder",
    "bench.runner": "bench.run.runner",
    "bench.store": "bench.results.store",
    "bench.tables": "bench.results.tables",
    "bench.tidy": "bench.results.tidy",
    "bench.tomlw": "bench.sweep.tomlw",
    "bench.units": "bench.run.units",
    "bench.warmup": "bench.run.warmup",
    "bench.windows": "models.windows",
    "bench.worktime": "bench.run.worktime",
}
#: the moved modules whose old name existed under ``radarbench`` too (they moved after it came)
MOVED_SINCE_PACKAGE = ("models.cfar_halves", "models.cfar_peaks", "models.cfar_regression",
                       "models.order_statistic", "bench._forkserver", "bench.baselines",
                       "bench.capabilities", "bench.claims", "bench.config", "bench.docs", "bench.executors",
                       "bench.failures", "bench.feasibility", "bench.figure_cache", "bench.grid",
                       "bench.identity", "bench.limits", "bench.listing", "bench.numba_cache", "bench.perf",
                       "bench.plan", "bench.processes", "bench.progress", "bench.provenance",
                       "bench.quantities", "bench.results.results_cache", "bench.results_cache", "bench.reuse", "bench.rng",
                       "bench.runfolder", "bench.runner", "bench.store", "bench.tables", "bench.tidy",
                       "bench.tomlw", "bench.units", "bench.warmup", "bench.windows", "bench.worktime")

_PREFIX = NEW_PACKAGE + "."


class OldImportName(DeprecationWarning):
    """An import of a name the distribution no longer installs at the top level."""


def new_name(old: str) -> str | None:
    """The import that replaces ``old``: ``models.kalman`` -> ``radarbench.models.kalman``,
    ``methods.imm`` -> ``radarbench.methods.kinematic.imm``, ``radarbench.models.cfar_halves``
    -> ``radarbench.models.cfar.halves``; None for a name not of ours (a current one included)."""
    if old.startswith(_PREFIX):
        inner = old[len(_PREFIX):]
        return _PREFIX + MOVED[inner] if inner in MOVED_SINCE_PACKAGE else None
    if old.split(".")[0] not in OLD_NAMES:
        return None
    return _PREFIX + MOVED.get(old, old)


#: the old modules whose name is now their family's folder (``methods.cfar``): the folder's
#: package answers the old name and lends the moved module's names (:func:`_lend`)
FOLDERS_NOW = tuple(old for old in MOVED if any(new.startswith(old + ".") for new in MOVED.values()))


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
        module = _module_of(fullname, new)
        _announce(fullname, new)
        return importlib.machinery.ModuleSpec(fullname, _AliasLoader(module), origin=getattr(module, "__file__", None),
                                              is_package=hasattr(module, "__path__"))


def _module_of(old: str, new: str):
    """The module that answers ``old``: its new home (:func:`new_name`), or the folder now
    of the same name (:data:`FOLDERS_NOW`); a new home that does not exist is one line."""
    if old in FOLDERS_NOW:
        return importlib.import_module(_PREFIX + old)
    try:
        return importlib.import_module(new)
    except ModuleNotFoundError as exc:
        if exc.name is None or not (new == exc.name or new.startswith(exc.name + ".")):
            raise                       # a module the new one imports is missing (an optional dependency)
        raise ModuleNotFoundError(_no_such_module(old, exc.name), name=old) from None


def _no_such_module(old: str, missing: str) -> str:
    """``No module named 'methods.foo'``, with what the package it would be in holds."""
    parent = sys.modules.get(missing.rpartition(".")[0])
    held = sorted(m.name for m in pkgutil.iter_modules(getattr(parent, "__path__", [])))
    where = f"; {parent.__name__} holds: {', '.join(held)}" if parent is not None and held else ""
    return f"No module named '{old}': its new name '{missing}' does not exist either{where}"


def _announce(old: str, new: str) -> None:
    """Once the old name ``old`` is answered by ``module``: the warning (unless the import
    system imports it as the parent of an old name, whose own warning is the one that
    matters), and the folders now named like an old module under it lend that module's names."""
    for folder in FOLDERS_NOW:
        if folder.rpartition(".")[0] == old or folder == old:
            _lend(importlib.import_module(_PREFIX + folder), _PREFIX + MOVED[folder])
    if not _parent_of_an_import(old):
        _warn(old, new)


def _lend(package, moved: str) -> None:
    """Let ``package`` (``radarbench.methods.cfar``) answer a name it lacks with the module
    ``moved`` (``radarbench.methods.cfar.detectors``), where the old module of the
    package's name now lives: ``from methods.cfar import CACFAR`` keeps working."""
    if "__getattr__" in vars(package):
        return

    def __getattr__(name: str):
        if not name.startswith("__"):
            try:
                return getattr(importlib.import_module(moved), name)
            except AttributeError:
                pass
        raise AttributeError(f"module {package.__name__!r} has no attribute {name!r}")

    package.__getattr__ = __getattr__


def _parent_of_an_import(name: str) -> bool:
    """Whether the import system is importing ``name`` as the parent of a module being
    imported (``methods`` for ``import methods.imm``): a ``_find_and_load`` of
    :mod:`importlib`'s bootstrap further up the stack loads a submodule of it."""
    frame = sys._getframe(1)
    while frame is not None:
        if frame.f_code.co_name == "_find_and_load" and _import_system(frame) and \
                str(frame.f_locals.get("name", "")).startswith(name + "."):
            return True
        frame = frame.f_back
    return False


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
    _announce(old, new)


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
