"""What produced a stored result: each config's code, data files and libraries
(docs/architecture.md, 'Identities').

A config's **identity** is a short hash of

* its **code**: the content of every module that computes its numbers — the plugin's
  module and, transitively, every module it loads (``import`` and ``from`` statements
  anywhere in a module, and ``importlib.import_module``/``__import__`` of a literal name),
  plus, for a method config, its task's module and the calibration; for a scenario
  config, its tasks' modules and the random streams (:mod:`bench.sweep.rng`). A plugin outside
  this package brings its whole top-level package (a registry that loads modules by a
  computed name is covered too). A module's content is its code with comments,
  docstrings, formatting and the module paths of its imports left out (an
  :func:`ast.dump`), or the file's bytes for a module without source (``.pyc``, an
  extension), so a comment, a docstring, a move or a rename changes no identity. Names
  are left out of the hash altogether: the code identity is the set of those contents,
  closed over the import graph (any edit of executed code reaches it; a move cannot).
* the harness's own modules only where they compute stored numbers: a harness module
  declares it with ``COMPUTES_RESULTS = True`` (the batched arithmetic, the tasks and
  their per-trial metrics, the calibration, the streams); the rest of ``bench/``
  (orchestration, report, command line) is in no identity and is never followed;
* the **libraries** it loads (any installed distribution other than its own, the
  Python standard library left out), by name and version, and always :data:`LIBRARIES`;
* the content of the **data files** it reads (:meth:`bench.core.Component.data_files`:
  by default the values of its ``kind="path"`` parameters), by content only.

The driver computes the identities once per run from the modules' files (parsed, never
executed again; each file parsed once per process while unchanged); the store stamps
each unit with its scenario config's identity and each (unit, method config) run with its
method config's (:mod:`bench.results.store`), and a run re-computes exactly the results whose
identity changed.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import importlib.machinery
import importlib.metadata
import importlib.util
import json
import os
import sys
from dataclasses import dataclass
from pathlib import Path

from radarbench.bench.results.provenance import package_owners

#: the libraries whose versions belong to every identity (their numerics are the results')
LIBRARIES = ("numpy", "scipy", "numba")
#: hex digits of a shown identity
SHORT = 12
#: how identities are computed; a store stamped by an earlier scheme is re-run once
SCHEME = 2
#: a harness module that computes stored numbers says so with this name bound to True
MARKER = "COMPUTES_RESULTS"

_PACKAGE = __name__.split(".")[0]
_PACKAGE_DIR = Path(sys.modules[_PACKAGE].__file__).resolve().parent
_HARNESS = Path(__file__).resolve().parents[1]
_INSTALLED = {"site-packages", "dist-packages"}
_MODULE_SUFFIXES = (".py", ".pyc", *importlib.machinery.EXTENSION_SUFFIXES)


def digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:SHORT]


def file_digest(path: str | Path) -> str:
    """The content hash of a file, read in blocks (a data file may be large)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()[:SHORT]


@functools.lru_cache(maxsize=None)
def library_versions() -> dict[str, str]:
    out = {}
    for name in LIBRARIES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


# --- one module: its content and what it loads -------------------------------------------

_IMPORTERS = {"import_module", "__import__"}


class _Content(ast.NodeTransformer):
    """What of a module's syntax tree is executed code, and what it loads, in one pass:
    docstrings dropped, and the module paths of imports (``from radarbench.models.kalman
    import KalmanFilter``, ``import a.b as c``) blanked, so a module moved or renamed leaves
    its importers' content as it was; :attr:`names`, the absolute dotted names the code may
    load, wherever the statement stands (``from a.b import c``: ``a.b`` and ``a.b.c``, since
    ``c`` may be a module; relative imports resolved; a call of ``importlib.import_module``
    or of the ``__import__`` builtin with a literal name)."""

    def __init__(self, module: str, is_package: bool):
        self.package = module if is_package else module.rpartition(".")[0]
        self.names: set[str] = set()

    def _body(self, node):
        self.generic_visit(node)
        body = node.body
        if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
                and isinstance(body[0].value.value, str):
            node.body = body[1:]         # a dump, never compiled: an empty body is fine
        return node

    visit_Module = visit_ClassDef = visit_FunctionDef = visit_AsyncFunctionDef = _body

    def visit_ImportFrom(self, node):
        base = node.module or ""
        if node.level:
            parts = self.package.split(".")
            parent = ".".join(parts[:len(parts) - node.level + 1])
            base = f"{parent}.{base}" if base else parent
        self.names.add(base)
        self.names.update(f"{base}.{alias.name}" for alias in node.names if alias.name != "*")
        node.module, node.level = None, 0
        return node

    def visit_Import(self, node):
        for alias in node.names:
            self.names.add(alias.name)
            if alias.asname:
                alias.name = ""
        return node

    def visit_Call(self, node):
        if node.args and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str) \
                and getattr(node.func, "attr", getattr(node.func, "id", None)) in _IMPORTERS:
            self.names.add(node.args[0].value.lstrip("."))
        self.generic_visit(node)
        return node


def _loaded_names(tree: ast.Module, module: str, is_package: bool) -> set[str]:
    """Absolute dotted names a module's code may load (:class:`_Content`)."""
    content = _Content(module, is_package)
    content.visit(tree)
    return content.names - {""}


def _with_parents(names) -> set[str]:
    """``a.b.c`` -> ``a``, ``a.b``, ``a.b.c``: importing a module runs its packages' ``__init__.py``."""
    return {".".join(n.split(".")[:i]) for n in names for i in range(1, n.count(".") + 2)}


def imported_names(source: str | bytes, module: str, is_package: bool = False) -> set[str]:
    """Absolute dotted names the source of ``module`` imports (see :func:`_loaded_names`)."""
    return _loaded_names(ast.parse(source), module, is_package)


def _marked(tree: ast.Module) -> bool:
    """Whether the module binds :data:`MARKER` to True at its top level."""
    return any(isinstance(node, ast.Assign) and isinstance(node.value, ast.Constant) and node.value.value is True
               and any(isinstance(t, ast.Name) and t.id == MARKER for t in node.targets) for node in tree.body)


@dataclass(frozen=True)
class Module:
    """One module file as the identity sees it."""

    content: str                # hash of its executed code (or of its bytes, without source)
    loads: frozenset[str]       # absolute dotted names it may load
    marked: bool                # binds COMPUTES_RESULTS = True


#: every module file this process's identities read (:func:`files_read`)
_READ: set[Path] = set()


def files_read() -> set[Path]:
    """The module files this process's identities were computed from (those no class
    imports among them), for :mod:`bench.results.unchanged`."""
    return set(_READ)


def read_module(name: str, file: Path) -> Module:
    """The module ``name`` in ``file``; parsed again only when the file changed (an edit
    between two runs of one process is seen)."""
    _READ.add(file)
    st = file.stat()
    return _parse_module(name, file, st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=4096)
def _parse_module(name: str, file: Path, _mtime_ns: int, _size: int) -> Module:
    data = file.read_bytes()
    key = hashlib.sha256(b"%s\0%s\0" % (name.encode(), file.name.encode()) + data).hexdigest()
    known = _parsed().get(key)
    if known is None:
        known = _parsed()[key] = _content_of(name, file, data)
        _parsed.new = True
    content, loads, marked = known
    return Module(content, frozenset(loads), marked)


def _content_of(name: str, file: Path, data: bytes) -> tuple[str, list[str], bool]:
    """(content hash, names it loads, marked) of a module file's bytes (see :class:`Module`)."""
    if file.suffix != ".py":                                   # no source: its bytes
        payload = data[16:] if file.suffix == ".pyc" else data  # a .pyc's header holds a timestamp
        return digest(payload), [], False
    try:
        tree = ast.parse(data, filename=str(file))
    except (SyntaxError, ValueError):                          # not ours to judge: its bytes
        return digest(data), [], False
    marked = _marked(tree)
    executed = _Content(name, file.name == "__init__.py")
    content = ast.dump(executed.visit(tree), annotate_fields=False, include_attributes=False)
    loads = sorted(_with_parents(executed.names - {""}))
    return digest(content.encode()), loads, marked


#: how many parsed modules the user's cache keeps (a module's entry is about 1 kB)
CACHED_MODULES = 4096


#: the user's cache of parsed modules (bench.sweep.listing.read_table)
PARSED_FILE = f"identity-modules-{SCHEME}.json"


@functools.lru_cache(maxsize=1)
def _parsed() -> dict[str, tuple[str, list[str], bool]]:
    """Parsed modules by the hash of their name and bytes: the user's cache, read once
    (parsing is most of an identity's cost)."""
    from radarbench.bench.sweep.listing import read_table
    return read_table(PARSED_FILE)


_parsed.new = False


def save_parsed() -> None:
    """Keep this process's parsed modules in the user's cache (the newest
    :data:`CACHED_MODULES`); a cache that cannot be written costs only speed."""
    from radarbench.bench.sweep.listing import write_table
    if _parsed.new and write_table(PARSED_FILE, _parsed(), CACHED_MODULES):
        _parsed.new = False


# --- where a module lives: ours, the harness, a library, the standard library -------------

@functools.lru_cache(maxsize=None)
def module_file(name: str) -> Path | None:
    """The file of module ``name`` (imported or not): its source, or its ``.pyc`` or
    extension when it has none; None for a name that is no module with a file (a
    built-in, a namespace package, an attribute such as ``a.b.Name``)."""
    module = sys.modules.get(name)
    origin = getattr(module, "__file__", None) if module is not None else None
    if origin is None and module is None:
        try:
            spec = importlib.util.find_spec(name)
        except Exception:       # noqa: BLE001 - finding "a.b.c" imports a.b, which may fail (a plugin's
            return None         # missing extra raises PluginError): c is then a name in it, not a module
        origin = spec.origin if spec is not None and spec.has_location else None
    if not origin or not origin.endswith(_MODULE_SUFFIXES):
        return None
    return Path(origin).resolve()


def _installed(path: Path) -> bool:
    return bool(_INSTALLED & set(path.parts))


def is_harness(path: Path) -> bool:
    """The harness's own files: ``bench/`` and the package's top files (``radarbench/__init__.py``)."""
    return path.is_relative_to(_HARNESS) or path.parent == _PACKAGE_DIR




@functools.lru_cache(maxsize=None)
def distribution_of(top: str) -> str:
    """"name version" of the installed distribution of top-level package ``top``, "" for none."""
    for name in package_owners().get(top) or []:
        try:
            dist = importlib.metadata.distribution(name)
        except importlib.metadata.PackageNotFoundError:
            continue
        return f"{dist.metadata['Name']} {dist.version}"
    return ""


@functools.lru_cache(maxsize=None)
def _own_tops(top: str, path: Path) -> frozenset[str]:
    """The top-level packages that are one plugin's own code: its distribution's, when it
    is installed, else its own."""
    if top == _PACKAGE or not _installed(path):
        return frozenset({top})
    names = set(package_owners().get(top) or [])
    return frozenset({t for t, ds in package_owners().items() if names & set(ds)} | {top})


def _package_files(top: str) -> list[tuple[str, Path]]:
    """(name, file) of every module file under the folder(s) of top-level package ``top``."""
    package = sys.modules.get(top)
    folders = list(getattr(package, "__path__", []) or [])
    out = []
    for folder in map(Path, folders):
        for path in sorted(folder.rglob("*")):
            if "__pycache__" in path.parts or not path.name.endswith(_MODULE_SUFFIXES) or not path.is_file():
                continue
            parts = path.relative_to(folder).with_suffix("").parts
            stem = parts[-1].split(".")[0]                     # an extension's name.cpython-311-x86_64...
            parts = parts[:-1] if stem == "__init__" else (*parts[:-1], stem)
            out.append((".".join((top, *parts)), path.resolve()))
    return out


# --- a config's code: the closure over what it loads --------------------------------------

@dataclass(frozen=True)
class CodeIdentity:
    hash: str
    distribution: str                        # "name version" of an installed plugin, else ""
    modules: tuple[tuple[str, str], ...]     # (module, its content hash), sorted: a description
    libraries: tuple[tuple[str, str], ...] = ()   # (distribution, version) it loads, sorted


def code_identity(*roots: str) -> CodeIdentity:
    """The code identity of the modules ``roots`` (the first: the plugin's) and all they
    load (see the module doc)."""
    first = module_file(roots[0])
    if first is None:
        raise LookupError(f"module {roots[0]!r} has no file: its code cannot be identified")
    top = roots[0].split(".")[0]
    own = _own_tops(top, first)
    libraries = dict(library_versions())
    modules = _closure([(name, None) for name in _with_parents(roots)], own, libraries)
    if top != _PACKAGE:
        modules.update(_closure(_unreached(own), own, libraries))
    contents = sorted(set(modules.values()))
    hashed = digest(json.dumps([contents, sorted(libraries.items())]).encode())
    return CodeIdentity(hashed, distribution_of(top) if top != _PACKAGE else "", tuple(sorted(modules.items())),
                        tuple(sorted(libraries.items())))


def _closure(todo: list[tuple[str, Path | None]], own: frozenset[str], libraries: dict[str, str]) -> dict[str, str]:
    """Module -> content of the modules ``todo`` ((name, file or None to find it)) and all
    they load, within a plugin's code (``own`` top-level packages, this package, code that
    is not installed); the libraries met are added to ``libraries`` (name -> version)."""
    modules: dict[str, str] = {}
    seen: set[str] = set()
    while todo:
        name, path = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        t = name.split(".")[0]
        if t in sys.stdlib_module_names:
            continue
        top_file = module_file(t)
        if top_file is not None and _installed(top_file) and t not in own and t != _PACKAGE:
            version = distribution_of(t)               # a library: its version, never its files
            if version:
                dist, _, number = version.rpartition(" ")
                libraries[dist] = number
            continue
        path = path or module_file(name)
        if path is None:
            continue
        module = read_module(name, path)
        if is_harness(path) and not module.marked:
            continue
        modules[name] = module.content
        todo += [(other, None) for other in sorted(module.loads - seen)]
    return modules


def _unreached(own: frozenset[str]) -> list[tuple[str, Path]]:
    """The modules of a plugin's packages that none of its registered classes reaches by
    its imports: what may be loaded by a computed name (a registry of its own, a
    ``importlib.import_module(f"...")``), hence part of every identity of that plugin."""
    from radarbench.bench import registry
    classes = [*registry.methods().values(), *registry.scenarios().values(),
               *(type(task) for task in registry.tasks().values())]
    reached: set[str] = set()
    for cls in classes:
        if cls.__module__.split(".")[0] in own:
            reached |= set(_closure([(name, None) for name in _with_parents([cls.__module__])], own, {}))
    return [(name, path) for t in sorted(own) for name, path in _package_files(t) if name not in reached]


def config_identity(cls: type, params, code: CodeIdentity | None = None) -> dict:
    """The identity of one config of plugin ``cls`` with ``params``: ``identity`` (the
    short hash), ``code``, ``distribution``, ``modules``, ``data`` (file -> hash) and
    ``versions`` (library -> version)."""
    code = code or code_identity(*config_roots(cls, params))
    data = {str(p): file_digest(p) for p in cls().data_files(params)}
    versions = dict(code.libraries)
    whole = json.dumps([code.hash, sorted(data.values())]).encode()
    return {"identity": digest(whole), "code": code.hash, "distribution": code.distribution,
            "modules": dict(code.modules), "data": data, "versions": versions}


def identity_roots(cls: type) -> tuple[str, ...]:
    """The modules whose code computes a config of ``cls``'s stored numbers: its own, and
    for a method its task's and the calibration's; for a scenario its tasks' and the
    random streams'."""
    from radarbench.bench import calibration, registry
    from radarbench.bench.sweep import rng
    from radarbench.bench.core import Method

    if isinstance(cls, type) and issubclass(cls, Method):
        tasks, harness = (cls.task,), calibration
    else:
        tasks, harness = tuple(getattr(cls, "tasks", ())), rng
    return (cls.__module__, *(type(registry.get_task(t)).__module__ for t in tasks), harness.__name__)


def config_roots(cls: type, params) -> tuple[str, ...]:
    """:func:`identity_roots` and the modules a config with ``params`` names besides
    (``Component.identity_modules``: the plugins it runs by name)."""
    return (*identity_roots(cls), *cls().identity_modules(params))


def plan_identities(plan) -> dict[str, dict[str, dict]]:
    """``{"scenarios": {label: identity}, "methods": {label: identity}}`` of a plan's configs."""
    from radarbench.bench import registry
    codes: dict[tuple[str, ...], CodeIdentity] = {}

    def of(cls: type, params) -> dict:
        roots = config_roots(cls, params)
        if roots not in codes:
            codes[roots] = code_identity(*roots)
        return config_identity(cls, params, codes[roots])

    identities = {"scenarios": {sc.label: of(registry.get_scenario(sc.name), sc.params) for sc in plan.scenarios},
                  "methods": {m.label: of(registry.get_method(m.name), m.params) for m in plan.methods}}
    save_parsed()
    return identities


#: where a run folder keeps the results its last run replaced (a store of its own)
PREVIOUS = "previous"


def _old_identities(store, units: list[str], runs: dict[str, set[str]]) -> dict[str, dict[str, list[str]]]:
    """Config label -> the identities (or "unrecorded") of the results about to be replaced:
    the scenario configs of the units replaced whole, the method configs of the other runs."""
    out: dict[str, dict[str, set]] = {"scenarios": {}, "methods": {}}
    for key in units:
        scenario, identity = store.db.execute("SELECT scenario, identity FROM units WHERE key=?", (key,)).fetchone()
        out["scenarios"].setdefault(scenario, set()).add(identity or "unrecorded")
    for key, methods in runs.items():
        for method in methods:
            (identity,) = store.db.execute("SELECT identity FROM runs WHERE unit=? AND method=?",
                                           (key, method)).fetchone()
            out["methods"].setdefault(method, set()).add(identity or "unrecorded")
    return {kind: {label: sorted(ids) for label, ids in table.items()} for kind, table in out.items()}


def content_keys(plan) -> dict:
    """What each config of ``plan`` computes, whatever its label: a key of its name and every
    parameter (a scenario's with the sweep's seed, which picks its streams), of the
    calibration, and the recorded trials (kept in the store's plan record, so an edited
    sweep can be matched against the results a folder holds: :func:`sweep_changes`)."""
    from radarbench.bench.params import params_as_dict
    from radarbench.bench.sweep.rng import stable_key

    def key(*parts) -> str:
        return f"{stable_key(list(parts)):016x}"
    calibration = plan.calibration
    return {"scenarios": {s.label: key(s.name, params_as_dict(s.params), plan.seed) for s in plan.scenarios},
            "methods": {m.label: key(m.name, params_as_dict(m.params)) for m in plan.methods},
            "calibration": key(calibration.pfa, calibration.mode, calibration.h0_trials, calibration.chance_pd),
            "record_trials": plan.record_trials}


@dataclass
class SweepChange:
    """How an edited sweep meets the results a run folder holds (:func:`sweep_changes`)."""

    units: list[str]                  # stored units the sweep no longer asks for, as they are
    runs: dict[str, set[str]]         # unit -> stored method configs it no longer asks for on it
    added: dict[str, set[str]]        # unit kept -> method configs it asks for that are not stored
    kept_units: int = 0
    edited: bool = False              # the sweep is not the one the store was written by

    def __bool__(self) -> bool:
        return self.edited


def sweep_changes(store, plan) -> SweepChange:
    """The results of ``store`` that ``plan`` (the sweep as edited since the store was
    written) still asks for, by what computed them rather than by the sweep: a unit is kept
    when the plan has it (same scenario config label, SNR level and trials) and its scenario
    config is the same (every parameter, the seed; its recorded trials unchanged), a run
    on it when its method config is the same and still pairs with the scenario config (for
    a run of a calibrated task, the calibration unchanged too). Nothing when the sweep did
    not change."""
    from radarbench.bench import registry
    from radarbench.bench.run.units import calibrated_configs, plan_units

    old = json.loads(store.meta("plan") or "null")
    if old is None or store.meta("fingerprint") == plan.fingerprint():
        return SweepChange([], {}, {})
    before, now = old.get("contents"), content_keys(plan)
    cal_units, eval_units = plan_units(plan)
    wanted = {u.key: u for u in cal_units + eval_units}
    recorded = max(now["record_trials"], (before or {}).get("record_trials", 0))
    change = SweepChange([], {}, {}, edited=True)
    for key, scenario, phase, trial_start in store.db.execute("SELECT key, scenario, phase, trial_start FROM units"):
        unit = wanted.get(key)
        if before is None or unit is None or before["scenarios"].get(scenario) != now["scenarios"][scenario] or \
                (phase == "evaluation" and before["record_trials"] != now["record_trials"] and trial_start < recorded):
            change.units.append(key)
            continue
        change.kept_units += 1
        sc = plan.scenarios[unit.scenario_index]
        expected = {m.label: m for m in (calibrated_configs(plan, sc) if phase == "calibration" else plan.pairs(sc))}
        stored = {m for (m,) in store.db.execute("SELECT method FROM runs WHERE unit=?", (key,))}
        recalibrated = before["calibration"] != now["calibration"]       # thresholds, and the nominal one stored
        gone = {m for m in stored if m not in expected or before["methods"].get(m) != now["methods"][m] or
                (recalibrated and registry.get_task(registry.get_method(expected[m].name).task).calibrated)}
        if gone:
            change.runs[key] = gone
        if set(expected) - (stored - gone):
            change.added[key] = set(expected) - (stored - gone)
    return change


def set_aside_changed(store, plan, out_dir: Path, quiet: bool = False) -> dict[str, set[str]]:
    """Match ``store`` with ``plan``: bind it to the identities of ``plan``'s configs now,
    and move the stored results that no longer match them, or that the sweep (if it was
    edited since) no longer asks for (:func:`sweep_changes`), into ``out_dir/previous/``
    (:meth:`bench.results.store.Store.set_aside`), saying so in one line each; returns the (unit ->
    method configs) runs to compute on the units kept (the units set aside whole are
    simply no longer stored)."""
    from radarbench.bench.results import runfolder
    from radarbench.bench.results.store import Store

    change = sweep_changes(store, plan)
    earlier_scheme = store.meta("identity_scheme") != str(SCHEME)
    store.use_identities(plan_identities(plan))
    store.set_meta("identity_scheme", str(SCHEME))
    units, runs = store.stale()
    units = sorted(set(units) - set(change.units))
    runs = {u: ms - change.runs.get(u, set()) for u, ms in runs.items() if u not in change.units}
    runs = {u: ms for u, ms in runs.items() if ms}
    if not (units or runs or change):
        return {}
    old = _old_identities(store, units, runs)
    folder = runfolder.folder_for(Path(out_dir) / PREVIOUS)
    if runfolder.read_manifest(Path(out_dir)) is not None:
        runfolder.claim(Path(out_dir), [f"{PREVIOUS}/{name}" for name in runfolder.STORE_FILES])
    previous = Store(folder / runfolder.STORE)
    aside = {u: runs.get(u, set()) | change.runs.get(u, set()) for u in {*runs, *change.runs}}
    try:
        store.set_aside(units + change.units, aside, previous)
    finally:
        previous.close()
    store.set_meta("replaced", json.dumps(old))
    if not quiet and (units or runs):
        print(_changed_line(old, store.stamps, len(units), sum(map(len, runs.values())), Path(out_dir),
                            earlier_scheme), file=sys.stderr)
    if not quiet and change:
        print(_sweep_line(change, Path(out_dir)), file=sys.stderr)
    return {u: runs.get(u, set()) | change.added.get(u, set()) for u in {*runs, *change.added}}


def _sweep_line(change: SweepChange, out_dir: Path) -> str:
    """One line: what of the folder's results an edited sweep reuses, computes and sets aside."""
    added = sum(map(len, change.added.values()))
    aside = [f"{n} {what}" for n, what in ((len(change.units), "units"),
                                           (sum(map(len, change.runs.values())), "(unit, method config) runs")) if n]
    return (f"the sweep changed: reusing {change.kept_units} stored units"
            + (f", computing {added} (unit, method config) runs on them" if added else "")
            + " and the units it adds"
            + (f"; {' and '.join(aside)} it no longer asks for are in {out_dir / PREVIOUS}" if aside else ""))


def _changed_line(old: dict, new: dict, units: int, runs: int, out_dir: Path, earlier_scheme: bool) -> str:
    """One line: which configs re-run, from which identity to which, and where the old results are."""
    changes = [f"{label} {'/'.join(ids)} -> {new[kind].get(label, '?')}"
               for kind in ("scenarios", "methods") for label, ids in old[kind].items()]
    shown = "; ".join(changes[:4]) + (f"; and {len(changes) - 4} more" if len(changes) > 4 else "")
    if all(ids == ["unrecorded"] for table in old.values() for ids in table.values()):
        why = "stored without a recorded identity (by an earlier bench)"
    elif earlier_scheme:
        why = ("stamped by an earlier bench, whose identities hashed module sources by name "
               "(now by content: a one-time re-run)")
    else:
        why = "code or data changed"
    what = " and ".join(part for part in (f"{units} units" if units else "",
                                          f"{runs} (unit, method config) runs" if runs else "") if part)
    return (f"{why}: re-running {what} ({shown}); the results they replace are in {out_dir / PREVIOUS} "
            f"(bench compare {out_dir / PREVIOUS} {out_dir})")
