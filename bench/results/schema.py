"""The results store's schema and its faults as one line, without NumPy or pandas: what the
run folder's checks (:mod:`bench.results.runfolder`) need before a command imports anything
heavy. The store itself is :mod:`bench.results.store`."""

from __future__ import annotations

import os
import sqlite3
from pathlib import Path

from radarbench.bench.errors import ConfigError, Fault, space_hint

SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS units (
    key TEXT PRIMARY KEY, phase TEXT NOT NULL, scenario TEXT NOT NULL, snr_db REAL,
    trial_start INTEGER NOT NULL, n INTEGER NOT NULL, generate_seconds REAL NOT NULL,
    finished REAL NOT NULL, identity TEXT);
CREATE TABLE IF NOT EXISTS runs (
    unit TEXT NOT NULL, method TEXT NOT NULL, seconds REAL NOT NULL, error TEXT,
    identity TEXT, traceback TEXT, PRIMARY KEY (unit, method));
CREATE TABLE IF NOT EXISTS identities (identity TEXT PRIMARY KEY, description TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS metrics (
    unit TEXT NOT NULL, method TEXT NOT NULL, data BLOB NOT NULL, PRIMARY KEY (unit, method));
CREATE TABLE IF NOT EXISTS null_stats (
    unit TEXT NOT NULL, scenario TEXT NOT NULL, method TEXT NOT NULL, nominal REAL,
    data BLOB NOT NULL, peaks BLOB, cells BLOB, PRIMARY KEY (unit, method));
CREATE TABLE IF NOT EXISTS records (
    unit TEXT NOT NULL, trial INTEGER NOT NULL, data BLOB NOT NULL, PRIMARY KEY (unit, trial));
"""


#: (table, column, type) added since the first stores: an earlier store gets them, NULL
MIGRATIONS = (("null_stats", "cells", "BLOB"), ("units", "identity", "TEXT"), ("runs", "identity", "TEXT"),
              ("runs", "traceback", "TEXT"))


def store_fault(path: str | Path, exc: sqlite3.Error) -> ConfigError | Fault:
    """The one-line error for an SQLite failure on the store at ``path``: a file that is
    not a (readable) store is bad input (exit 2); the rest is the machine's (exit 3:
    disk full, file-size limit, read-only, I/O)."""
    name = getattr(exc, "sqlite_errorname", "") or ""
    if name.startswith(("SQLITE_CORRUPT", "SQLITE_NOTADB")):
        return ConfigError(str(path), f"not a readable bench results store ({exc}); move it away, "
                                      "or discard it with --fresh")
    hint = space_hint(path) if name.startswith(("SQLITE_FULL", "SQLITE_IOERR")) else ""
    return Fault(str(path), f"store failed: {exc}{hint}")


def damaged(path: str | Path, why: str) -> ConfigError:
    """The one-line error for a bench store whose content is damaged (exit 2); the advice
    is the one ``bench run`` rewrites into "--fresh discards it" where --fresh can."""
    return ConfigError(str(path), f"damaged bench results store ({why}); move it away, or choose another folder")


def read_only_uri(db: Path) -> str:
    """The SQLite URI that reads the store ``db`` without writing anything: ``mode=ro``, and
    ``immutable=1`` when it has no write-ahead log (then the file alone holds every commit;
    ``mode=ro`` alone would create ``-wal``/``-shm`` beside it, or fail on read-only media).
    With a log (a run in progress, or one killed), ``mode=ro`` reads its commits too, on
    read-only media as well."""
    has_wal = os.path.exists(db.with_name(f"{db.name}-wal")) and os.path.exists(db.with_name(f"{db.name}-shm"))
    return f"{db.absolute().as_uri()}?mode=ro" + ("" if has_wal else "&immutable=1")
