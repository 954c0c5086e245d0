"""The evaluation store of a study: one SQLite database, written before the loop moves on.

Schema (``study.sqlite`` in the study folder; WAL journal, one transaction per write):

``meta(key TEXT PRIMARY KEY, value TEXT)``
    study-level facts as JSON: the study file's fingerprint, the seed, the parameter space.

``evaluations``
    ``id`` INTEGER PRIMARY KEY, ``kind`` ('fit' | 'validation' | 'screen'), ``iteration`` (0 =
    initial design; for screening the stage), ``slot`` (position in its batch),
    ``speed_setting``, ``params`` (JSON, SI units),
    ``status`` ('pending' | 'ok' | 'failed' | 'unstable' | 'timeout'), ``cost``, ``dtw_xy`` [m],
    ``dtw_theta`` [rad], ``transit_time`` [s], ``seed``, ``wall_time`` [s], ``asked_at`` and
    ``finished_at`` (Unix time [s]), ``run_file`` (trajectory file, relative to the study
    folder), ``details`` (JSON: validation criteria, diagnostics).

A batch is written as ``pending`` rows before any of it runs; each result replaces its row in one
transaction the moment it arrives. A study killed at any point therefore finds on restart every
finished evaluation (never simulated again) and exactly the pending ones to run.

A new store is created under a temporary name and renamed once its schema is written, so an
existing ``study.sqlite`` always has one: an empty (0-byte) or unreadable file is damaged and
refused, never silently restarted. ``readonly=True`` (``status``, ``report``) opens the file with
SQLite's ``mode=ro`` and never writes to it.
"""

from __future__ import annotations

import json
import os
import sqlite3
import time
import urllib.parse
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from parcelfit.errors import ParcelfitError

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS evaluations (
    id INTEGER PRIMARY KEY,
    kind TEXT NOT NULL CHECK (kind IN ('fit', 'validation', 'screen')),
    iteration INTEGER NOT NULL,
    slot INTEGER NOT NULL,
    speed_setting INTEGER NOT NULL,
    params TEXT NOT NULL,
    status TEXT NOT NULL,
    cost REAL, dtw_xy REAL, dtw_theta REAL, transit_time REAL,
    seed INTEGER, wall_time REAL, asked_at REAL NOT NULL, finished_at REAL,
    run_file TEXT, details TEXT,
    UNIQUE (kind, iteration, slot)
);
"""


@dataclass(frozen=True)
class Evaluation:
    """One row of the store (see the module docstring for the units)."""

    id: int
    kind: str
    iteration: int
    slot: int
    speed_setting: int
    params: dict[str, float]
    status: str
    cost: float | None
    dtw_xy: float | None
    dtw_theta: float | None
    transit_time: float | None
    seed: int | None
    wall_time: float | None
    asked_at: float
    finished_at: float | None
    run_file: str | None
    details: dict[str, Any]


class Store:
    """Durable record of a study's evaluations (SQLite, WAL, one transaction per write)."""

    def __init__(self, path: str | Path, *, readonly: bool = False) -> None:
        self.path = Path(path)
        self.readonly = readonly
        if self.path.is_file() and self.path.stat().st_size == 0:
            raise ParcelfitError(
                "the study database is empty (0 bytes): it was truncated or damaged, and the "
                "results it held are not in it",
                file=self.path,
                fix="restore it from a backup, or run the study in a new output folder "
                "(this one is left untouched)",
            )
        try:
            if readonly:
                self._db = self._open_readonly()
            else:
                if not self.path.exists():
                    self._create()
                self._db = sqlite3.connect(self.path, timeout=30.0, isolation_level=None)
                self._db.execute("PRAGMA journal_mode=WAL")
                self._db.execute("PRAGMA synchronous=FULL")
                self._db.executescript(_SCHEMA)
        except sqlite3.DatabaseError as exc:
            raise self._error(exc) from exc

    def _create(self) -> None:
        """Write the schema under a temporary name, then rename: a store never exists half made."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_name(f"{self.path.name}.{os.getpid()}.new")
        for stale in (tmp, Path(f"{tmp}-wal"), Path(f"{tmp}-shm")):
            stale.unlink(missing_ok=True)
        db = sqlite3.connect(tmp, isolation_level=None)
        try:
            db.execute("PRAGMA journal_mode=WAL")
            db.executescript(_SCHEMA)
        finally:
            db.close()
        os.replace(tmp, self.path)

    def _open_readonly(self) -> sqlite3.Connection:
        if not self.path.is_file():
            raise ParcelfitError("no study database here", file=self.path)
        uri = "file:" + urllib.parse.quote(str(self.path.resolve()))
        try:
            db = sqlite3.connect(f"{uri}?mode=ro", uri=True, timeout=30.0, isolation_level=None)
            db.execute("SELECT count(*) FROM sqlite_master").fetchone()
        except sqlite3.OperationalError:
            # a WAL database in a read-only folder without its -shm file: SQLite can read it
            # only as immutable (nobody can write there either)
            db = sqlite3.connect(f"{uri}?mode=ro&immutable=1", uri=True, isolation_level=None)
        tables = {r[0] for r in db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        if not {"meta", "evaluations"} <= tables:
            db.close()
            raise ParcelfitError(
                "this is not a parcelfit study database (its tables are missing)",
                file=self.path,
                fix="point at a study folder written by parcelfit",
            )
        return db

    def _error(self, exc: sqlite3.Error) -> ParcelfitError:
        """A database error as a message that says what to do without endangering results."""
        if "readonly" in str(exc) or "read-only" in str(exc):
            return ParcelfitError(
                "the study folder or its database is read-only, so the study cannot go on "
                "(its results are intact)",
                file=self.path,
                fix="make the folder and study.sqlite writable, or copy the folder somewhere "
                "writable and run there",
            )
        return ParcelfitError(
            f"cannot open the study database ({exc})",
            file=self.path,
            fix="restore it from a backup, or run the study in a new output folder",
        )

    def close(self) -> None:
        """Close the database."""
        self._db.close()

    @contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        if self.readonly:
            raise ParcelfitError("this store was opened read-only", file=self.path)
        try:
            self._db.execute("BEGIN IMMEDIATE")
        except sqlite3.OperationalError as exc:
            raise (self._error(exc) if "readonly" in str(exc) else exc) from exc
        try:
            yield self._db
        except sqlite3.OperationalError as exc:
            self._db.execute("ROLLBACK")
            raise (self._error(exc) if "readonly" in str(exc) else exc) from exc
        except BaseException:
            self._db.execute("ROLLBACK")
            raise
        self._db.execute("COMMIT")

    # -- meta -------------------------------------------------------------------------------
    def get_meta(self, key: str) -> Any:
        """A study-level value (None if absent)."""
        row = self._db.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        return None if row is None else json.loads(row[0])

    def set_meta(self, key: str, value: Any) -> None:
        """Store a study-level value (JSON-serialisable)."""
        with self._transaction() as db:
            db.execute(
                "INSERT OR REPLACE INTO meta (key, value) VALUES (?, ?)", (key, json.dumps(value))
            )

    # -- evaluations ------------------------------------------------------------------------
    def add_pending(
        self,
        kind: str,
        iteration: int,
        batch: Sequence[Mapping[str, float]],
        speed_setting: int,
        seeds: Sequence[int],
    ) -> list[int]:
        """Record a batch as pending (one transaction); returns the row ids in batch order."""
        now = time.time()
        ids = []
        with self._transaction() as db:
            for slot, (params, seed) in enumerate(zip(batch, seeds, strict=True)):
                cur = db.execute(
                    "INSERT INTO evaluations (kind, iteration, slot, speed_setting, params, status, seed, asked_at) "
                    "VALUES (?, ?, ?, ?, ?, 'pending', ?, ?)",
                    (kind, iteration, slot, speed_setting, json.dumps(dict(params)), seed, now),
                )
                ids.append(int(cur.lastrowid))  # type: ignore[arg-type]
        return ids

    def finish(
        self,
        row_id: int,
        *,
        status: str,
        cost: float | None = None,
        dtw_xy: float | None = None,
        dtw_theta: float | None = None,
        transit_time: float | None = None,
        wall_time: float | None = None,
        run_file: str | None = None,
        details: Mapping[str, Any] | None = None,
    ) -> None:
        """Record the result of a pending evaluation (one transaction)."""
        if status == "pending":
            raise ParcelfitError("a finished evaluation needs a final status")
        with self._transaction() as db:
            cur = db.execute(
                "UPDATE evaluations SET status = ?, cost = ?, dtw_xy = ?, dtw_theta = ?, transit_time = ?, "
                "wall_time = ?, finished_at = ?, run_file = ?, details = ? WHERE id = ?",
                (
                    status,
                    cost,
                    dtw_xy,
                    dtw_theta,
                    transit_time,
                    wall_time,
                    time.time(),
                    run_file,
                    json.dumps(dict(details or {}), default=str),
                    row_id,
                ),
            )
            if cur.rowcount != 1:
                raise ParcelfitError(f"no evaluation with id {row_id} in {self.path}")

    def reopen(self, row_ids: Sequence[int]) -> None:
        """Make finished evaluations pending again (one transaction), so they run on resume."""
        with self._transaction() as db:
            for row_id in row_ids:
                db.execute(
                    "UPDATE evaluations SET status = 'pending', cost = NULL, dtw_xy = NULL, "
                    "dtw_theta = NULL, transit_time = NULL, wall_time = NULL, finished_at = NULL, "
                    "run_file = NULL, details = NULL WHERE id = ?",
                    (row_id,),
                )

    def evaluations(self, kind: str | None = None) -> list[Evaluation]:
        """All evaluations (of one kind), in the order they were asked."""
        sql = "SELECT * FROM evaluations" + (" WHERE kind = ?" if kind else "") + " ORDER BY id"
        rows = self._db.execute(sql, (kind,) if kind else ()).fetchall()
        out = []
        for r in rows:
            out.append(
                Evaluation(
                    id=r[0],
                    kind=r[1],
                    iteration=r[2],
                    slot=r[3],
                    speed_setting=r[4],
                    params=json.loads(r[5]),
                    status=r[6],
                    cost=r[7],
                    dtw_xy=r[8],
                    dtw_theta=r[9],
                    transit_time=r[10],
                    seed=r[11],
                    wall_time=r[12],
                    asked_at=r[13],
                    finished_at=r[14],
                    run_file=r[15],
                    details=json.loads(r[16]) if r[16] else {},
                )
            )
        return out
