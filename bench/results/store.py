"""The results store: one SQLite file per run folder (``results.sqlite``, WAL).

Only the driver process writes, one transaction per finished unit, so a run
stopped at any moment (Ctrl-C, ``kill -9``, a crash) holds exactly the units
that finished; started again, the run skips them (:meth:`Store.done_units`) and
ends with the results of an uninterrupted run.

Arrays are stored as ``.npy``/``.npz`` bytes (never pickle).

Tables
------
meta        key/value: plan fingerprint, the plan as JSON, creation time, the current
            identities of the configs (JSON)
units       one row per finished unit (phase, scenario, SNR, trial range, timing) and the
            identity of its scenario config (NULL: stored by a bench that recorded none)
runs        one row per (unit, method config): seconds, error and traceback (NULL if
            fine), the identity of the method config
identities  each identity a run of this folder recorded, described (JSON: code, modules,
            data files, library versions; :mod:`bench.run.identity`)
metrics     per (unit, method config): the per-trial metric columns (npz)
null_stats  per (calibration unit, method config): null-hypothesis statistic
            values used for calibration (npy) and the nominal threshold
records     per recorded trial: a serialised :class:`bench.recording.TrialRecord`
"""

from __future__ import annotations

import contextlib
import io
import json
import sqlite3
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np
import pandas as pd

from radarbench.bench.errors import ConfigError
# the schema and the store's faults, light (the run folder's checks import them without NumPy); importable from here
from radarbench.bench.results.schema import MIGRATIONS, SCHEMA, damaged, read_only_uri, store_fault  # noqa: F401

@dataclass
class MethodRun:
    """What one method config produced on one unit."""

    label: str
    seconds: float
    error: str | None = None
    traceback: str | None = None                   # the failure's full traceback
    metrics: dict[str, np.ndarray] | None = None   # evaluation units: per-trial columns
    null_values: np.ndarray | None = None          # calibration units: null statistic values
    null_peaks: np.ndarray | None = None           # calibration units: per-trial window peaks
    null_cells: np.ndarray | None = None           # calibration units: per-trial cell order statistics
    nominal_threshold: float | None = None         # calibration units


@dataclass
class UnitResult:
    """Everything a worker returns for one unit of work."""

    key: str
    phase: str                      # "calibration" | "evaluation"
    scenario: str                   # scenario config label
    snr_db: float | None
    trial_start: int
    n: int
    generate_seconds: float
    runs: list[MethodRun] = field(default_factory=list)
    common: dict[str, np.ndarray] = field(default_factory=dict)  # per-trial columns shared by methods
    records: list[tuple[int, bytes]] = field(default_factory=list)
    snr_definition: str = ""        # the scenario's SNR definition, one sentence


def array_to_bytes(a: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(a), allow_pickle=False)
    return buf.getvalue()


def bytes_to_array(b: bytes) -> np.ndarray:
    return np.load(io.BytesIO(b), allow_pickle=False)


def columns_to_bytes(cols: dict[str, np.ndarray]) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **{k: np.asarray(v) for k, v in cols.items()})
    return buf.getvalue()


def bytes_to_columns(b: bytes) -> dict[str, np.ndarray]:
    with np.load(io.BytesIO(b), allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _merge_record(old: bytes, new: bytes, labels: set[str], order: list[str]) -> bytes:
    """A stored trial record with the traces of method configs ``labels`` taken from ``new``
    (kept in plan order, as an uninterrupted run writes them)."""
    from radarbench.bench.recording.record import TrialRecord

    rec, fresh = TrialRecord.from_bytes(old), TrialRecord.from_bytes(new)
    traces = {**rec.methods, **{k: v for k, v in fresh.methods.items() if k in labels}}
    rank = {label: i for i, label in enumerate(order)}
    rec.methods = dict(sorted(traces.items(), key=lambda kv: rank.get(kv[0], len(rank))))
    return rec.to_bytes()


class Store:
    """Writes are transactions (``BEGIN IMMEDIATE``: a check and the write that depends
    on it see one state of the store, whoever else writes)."""

    def __init__(self, path: str | Path, *, read_only: bool = False):
        self.path = Path(path)
        #: the identities units and runs are stamped with as they are saved (use_identities)
        self.stamps: dict[str, dict[str, str]] = {"scenarios": {}, "methods": {}}
        if read_only:       # bench compare: reads, and creates or changes no file (works on read-only media)
            try:
                self.db = sqlite3.connect(read_only_uri(self.path), uri=True, timeout=30, isolation_level=None)
            except sqlite3.Error as exc:
                raise store_fault(self.path, exc) from None
            return
        # isolation_level=None: no implicit transactions; writes use _write().
        self.db = sqlite3.connect(self.path, timeout=30, isolation_level=None)
        try:
            self.db.execute("PRAGMA journal_mode=WAL")
            self.db.execute("PRAGMA synchronous=NORMAL")
            with self._write():
                for statement in SCHEMA.split(";"):
                    if statement.strip():
                        self.db.execute(statement)
                for table, column, kind in MIGRATIONS:      # columns a store of an earlier bench lacks
                    columns = {row[1] for row in self.db.execute(f"PRAGMA table_info({table})")}
                    if column not in columns:
                        self.db.execute(f"ALTER TABLE {table} ADD COLUMN {column} {kind}")
        except sqlite3.Error as exc:
            self.db.close()
            raise store_fault(self.path, exc) from None

    @contextlib.contextmanager
    def _write(self):
        """One write transaction, taken at once (``BEGIN IMMEDIATE``), committed at the end,
        rolled back on any error."""
        self.db.execute("BEGIN IMMEDIATE")
        try:
            yield
        except BaseException:
            self.db.rollback()
            raise
        self.db.commit()

    def close(self) -> None:
        self.db.close()

    # ---------------------------------------------------------------- plan
    def bind_plan(self, fingerprint: str, plan: dict) -> None:
        """Tie the store to a plan (the sweep as run now: the results it no longer asks for
        were set aside first, :func:`bench.run.identity.set_aside_changed`)."""
        with self._write():
            self.db.execute("INSERT OR REPLACE INTO meta VALUES ('fingerprint', ?)", (fingerprint,))
            self.db.execute("INSERT OR REPLACE INTO meta VALUES ('plan', ?)", (json.dumps(plan),))
            self.db.execute("INSERT OR IGNORE INTO meta VALUES ('created', ?)", (repr(time.time()),))

    def meta(self, key: str) -> str | None:
        row = self.db.execute("SELECT value FROM meta WHERE key=?", (key,)).fetchone()
        return None if row is None else row[0]

    def set_meta(self, key: str, value: str) -> None:
        with self._write():
            self.db.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)", (key, value))

    def plan(self) -> dict:
        text = self.meta("plan")
        if text is None:
            raise ConfigError("", f"{self.path} holds no plan (not a bench run folder?)")
        with self._decoding("the stored plan"):
            return json.loads(text)

    @contextlib.contextmanager
    def _decoding(self, what: str):
        """Stored content that does not decode (the plan's JSON, an array's bytes) is a
        damaged store: one line naming the file, exit 2 (:func:`damaged`)."""
        try:
            yield
        except (ValueError, KeyError, EOFError, OSError, zipfile.BadZipFile) as exc:
            raise damaged(self.path, f"{what} cannot be read: {type(exc).__name__}: {exc}"[:300]) from None

    # ---------------------------------------------------------------- identities
    def use_identities(self, described: dict[str, dict[str, dict]]) -> None:
        """Stamp what is saved from now on with ``described`` (:func:`bench.run.identity.plan_identities`),
        and keep each identity's description."""
        self.stamps = {kind: {label: d["identity"] for label, d in table.items()} for kind, table in described.items()}
        with self._write():
            for table in described.values():
                for d in table.values():
                    self.db.execute("INSERT OR IGNORE INTO identities VALUES (?, ?)",
                                    (d["identity"], json.dumps(d, sort_keys=True)))
            self.db.execute("INSERT OR REPLACE INTO meta VALUES ('identities', ?)", (json.dumps(self.stamps),))

    def described(self, identity: str) -> dict | None:
        row = self.db.execute("SELECT description FROM identities WHERE identity=?", (identity,)).fetchone()
        return None if row is None else json.loads(row[0])

    def stale(self) -> tuple[list[str], dict[str, set[str]]]:
        """What no longer matches :attr:`stamps`: the units whose scenario config's identity
        changed (or was never recorded), and per other unit the method configs whose run's did."""
        units = [key for key, scenario, identity in self.db.execute("SELECT key, scenario, identity FROM units")
                 if identity is None or identity != self.stamps["scenarios"].get(scenario, identity)]
        gone = set(units)
        runs: dict[str, set[str]] = {}
        for unit, method, identity in self.db.execute("SELECT unit, method, identity FROM runs"):
            if unit not in gone and (identity is None or identity != self.stamps["methods"].get(method, identity)):
                runs.setdefault(unit, set()).add(method)
        return units, runs

    def set_aside(self, units: list[str], runs: dict[str, set[str]], previous: "Store") -> None:
        """Move the results of ``units`` (whole) and ``runs`` (unit -> method configs) into the
        store ``previous``, emptied first: it then holds the state they replace, with this
        store's plan, so ``bench compare`` can compare the two (docs/architecture.md,
        'Identities'). ``previous`` is written and committed before they leave this store:
        a crash in between leaves them here, and the next run sets them aside again."""
        for key in ("fingerprint", "plan", "created", "snr_definition", "units_total"):
            value = self.meta(key)
            if value is not None:
                previous.set_meta(key, value)
        pairs = [(u, m) for u in units for (m,) in self.db.execute("SELECT method FROM runs WHERE unit=?", (u,))]
        pairs += [(u, m) for u, methods in runs.items() for m in sorted(methods)]
        with previous._write():
            for table in ("units", "runs", "metrics", "null_stats", "records", "identities"):
                previous.db.execute(f"DELETE FROM {table}")
            for u in dict.fromkeys(u for u, _ in pairs):
                self._copy_rows(previous, "units", "key=?", (u,))
            for u, m in pairs:
                for table in ("runs", "metrics", "null_stats"):
                    self._copy_rows(previous, table, "unit=? AND method=?", (u, m))
            for (identity,) in self.db.execute("SELECT DISTINCT identity FROM runs UNION SELECT identity FROM units"):
                self._copy_rows(previous, "identities", "identity=?", (identity,))
        with self._write():
            for u, m in pairs:
                for table in ("runs", "metrics", "null_stats"):
                    self.db.execute(f"DELETE FROM {table} WHERE unit=? AND method=?", (u, m))
            for u in units:
                self.db.execute("DELETE FROM units WHERE key=?", (u,))
                self.db.execute("DELETE FROM records WHERE unit=?", (u,))

    def _copy_rows(self, other: "Store", table: str, where: str, args: tuple) -> None:
        """The rows of ``table`` matching ``where`` into the same table of ``other``, column by
        name (an earlier store's migrated columns come in another order)."""
        cursor = self.db.execute(f"SELECT * FROM {table} WHERE {where}", args)
        names = [c[0] for c in cursor.description]
        marks = ",".join("?" * len(names))
        other.db.executemany(f"INSERT OR REPLACE INTO {table} ({','.join(names)}) VALUES ({marks})", cursor.fetchall())

    # ---------------------------------------------------------------- units
    def done_units(self) -> set[str]:
        return {r[0] for r in self.db.execute("SELECT key FROM units")}

    def save_unit(self, r: UnitResult) -> bool:
        """Store one finished unit in a single transaction; returns whether anything was written.

        A unit is stored once: a second result for a stored unit (a unit dask ran
        again after losing a worker, a re-run with ``--retry-failed``, or of method
        configs whose code changed) only replaces the runs of method configs that
        *failed* in the stored result, and adds those it lacks (:meth:`set_aside`);
        everything else of it is ignored, so nothing is counted twice. The check and the
        write are one transaction, so two writers never both insert a unit.
        """
        with self._write():
            if self.db.execute("SELECT 1 FROM units WHERE key=?", (r.key,)).fetchone() is not None:
                return self._replace_failed_runs(r)
            self.db.execute("INSERT INTO units (key, phase, scenario, snr_db, trial_start, n, generate_seconds, "
                            "finished, identity) VALUES (?,?,?,?,?,?,?,?,?)",
                            (r.key, r.phase, r.scenario, r.snr_db, r.trial_start, r.n,
                             r.generate_seconds, time.time(), self.stamps["scenarios"].get(r.scenario)))
            self._insert_runs(r, r.runs)
            for trial, blob in r.records:
                self.db.execute("INSERT INTO records VALUES (?,?,?)", (r.key, trial, blob))
        return True

    def failed_runs(self) -> dict[str, set[str]]:
        """unit key -> method config labels whose run on that unit failed."""
        out: dict[str, set[str]] = {}
        for unit, method in self.db.execute("SELECT unit, method FROM runs WHERE error IS NOT NULL"):
            out.setdefault(unit, set()).add(method)
        return out

    def _replace_failed_runs(self, r: UnitResult) -> bool:
        """Within the caller's transaction: swap the stored failed runs of unit ``r.key``
        for the runs of ``r``, and add the runs it lacks (set aside when their code
        changed, :meth:`set_aside`); the other method configs' results stay untouched."""
        stored = dict(self.db.execute("SELECT method, error IS NOT NULL FROM runs WHERE unit=?", (r.key,)))
        runs = [run for run in r.runs if stored.get(run.label, True)]
        if not runs:
            return False
        for run in runs:
            for table in ("runs", "metrics", "null_stats"):
                self.db.execute(f"DELETE FROM {table} WHERE unit=? AND method=?", (r.key, run.label))
        self._insert_runs(r, runs)
        labels = {run.label for run in runs}
        order = [m["label"] for m in self.plan().get("methods", [])] if self.meta("plan") else []
        for trial, blob in r.records:
            row = self.db.execute("SELECT data FROM records WHERE unit=? AND trial=?", (r.key, trial)).fetchone()
            merged = blob if row is None else _merge_record(row[0], blob, labels, order)
            self.db.execute("INSERT OR REPLACE INTO records VALUES (?,?,?)", (r.key, trial, merged))
        return True

    def _insert_runs(self, r: UnitResult, runs: list[MethodRun]) -> None:
        for run in runs:
            self.db.execute("INSERT INTO runs (unit, method, seconds, error, identity, traceback) VALUES (?,?,?,?,?,?)",
                            (r.key, run.label, run.seconds, run.error, self.stamps["methods"].get(run.label),
                             run.traceback))
            if run.metrics is not None:
                cols = {**r.common, **run.metrics}
                self.db.execute("INSERT INTO metrics VALUES (?,?,?)",
                                (r.key, run.label, columns_to_bytes(cols)))
            if run.null_values is not None:
                peaks = None if run.null_peaks is None else array_to_bytes(run.null_peaks)
                cells = None if run.null_cells is None else array_to_bytes(run.null_cells)
                self.db.execute("INSERT INTO null_stats (unit, scenario, method, nominal, data, peaks, cells) "
                                "VALUES (?,?,?,?,?,?,?)", (r.key, r.scenario, run.label, run.nominal_threshold,
                                                           array_to_bytes(run.null_values), peaks, cells))

    # ---------------------------------------------------------------- reads
    def units(self) -> pd.DataFrame:
        return pd.read_sql_query("SELECT * FROM units ORDER BY key", self.db)

    def runs(self) -> pd.DataFrame:
        return pd.read_sql_query(
            "SELECT runs.unit, runs.method, runs.seconds, runs.error, runs.traceback, units.phase, units.scenario, "
            "units.snr_db, units.n FROM runs JOIN units ON runs.unit = units.key ORDER BY runs.unit, runs.method",
            self.db)

    def iter_metrics(self) -> Iterator[tuple[str, str, str, float | None, dict[str, np.ndarray]]]:
        """(unit, method, scenario, snr_db, columns) for every evaluation result."""
        q = ("SELECT metrics.unit, metrics.method, units.scenario, units.snr_db, metrics.data "
             "FROM metrics JOIN units ON metrics.unit = units.key ORDER BY units.scenario, "
             "metrics.method, units.snr_db, units.trial_start")
        for unit, method, scenario, snr, blob in self.db.execute(q):
            with self._decoding(f"the metrics of {method!r} on unit {unit!r}"):
                columns = bytes_to_columns(blob)
            yield unit, method, scenario, snr, columns

    def null_values(self, scenario: str, method: str) -> tuple[np.ndarray, np.ndarray | None, float | None]:
        """Pooled null statistic values of a method config (in unit order), its
        per-trial window peaks (None if the scenario gives no window) and its
        nominal threshold."""
        rows = self.db.execute("SELECT data, peaks, nominal FROM null_stats WHERE scenario=? AND method=? "
                               "ORDER BY unit", (scenario, method)).fetchall()
        if not rows:
            return np.empty(0), None, None
        with self._decoding(f"the null values of {method!r} on {scenario!r}"):
            values = np.concatenate([bytes_to_array(r[0]) for r in rows])
            peaks = None if any(r[1] is None for r in rows) else \
                np.concatenate([bytes_to_array(r[1]) for r in rows])
        return values, peaks, rows[0][2]

    def null_cells(self, scenario: str, method: str) -> np.ndarray | None:
        """Per null trial, the order statistics of its cell values (see
        :func:`bench.calibration.cell_order_statistics`), stacked (trials, 2, R);
        None if the task keeps none or a unit lacks them."""
        rows = self.db.execute("SELECT cells FROM null_stats WHERE scenario=? AND method=? ORDER BY unit",
                               (scenario, method)).fetchall()
        if not rows or any(r[0] is None for r in rows):
            return None
        with self._decoding(f"the null cell statistics of {method!r} on {scenario!r}"):
            return np.concatenate([bytes_to_array(r[0]) for r in rows])

    def null_trial_lengths(self, scenario: str, method: str) -> np.ndarray:
        """How many of :meth:`null_values` each null trial contributed, in the same
        order (a unit's trials contribute equally), so rates over those values can
        be counted per trial."""
        rows = self.db.execute("SELECT null_stats.data, units.n FROM null_stats JOIN units ON "
                               "null_stats.unit = units.key WHERE null_stats.scenario=? AND "
                               "null_stats.method=? ORDER BY null_stats.unit", (scenario, method)).fetchall()
        with self._decoding(f"the null values of {method!r} on {scenario!r}"):
            return np.concatenate([np.full(n, bytes_to_array(data).size // n, dtype=np.int64)
                                   for data, n in rows]) if rows else np.empty(0, np.int64)

    def records(self) -> list[bytes]:
        q = ("SELECT records.data FROM records JOIN units ON records.unit = units.key "
             "ORDER BY units.scenario, units.snr_db, records.trial")
        return [r[0] for r in self.db.execute(q)]
