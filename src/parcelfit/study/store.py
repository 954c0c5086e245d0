"""The evaluation store of a study: one SQLite database, written before the loop moves on.

Schema (``study.sqlite`` in the study folder; WAL journal, one transaction per write):

``meta(key TEXT PRIMARY KEY, value TEXT)``
    study-level facts as JSON. Three of them are typed records with one writer and one reader
    here: ``study`` (`StudyRecord`: name, parameter space, batch size, seed, speed settings and
    the optimiser as it ran, `OptimizerRecord`), ``source`` (`SourceRecord`: the study file,
    dataset, rig and consignment) and ``recommended`` (`RecommendedRecord`: the parameters the
    study validates and reports, with their cost). The others are plain values:
    ``fingerprint`` (of the study file), ``reference_run`` and ``stop_reason``; a screen's
    store holds ``placements`` (per design row, which a rerun must match).

``evaluations``
    ``id`` INTEGER PRIMARY KEY, ``kind`` ('fit' | 'validation' | 'screen'; in the stores of a
    twin dataset and of a precision check 'twin' | 'precision'), ``iteration`` (0 =
    initial design; for screening the stage), ``slot`` (position in its batch; a screen
    over K > 1 placements: design row x K + placement seed - 1; a twin run: its job's index),
    ``speed_setting``, ``params`` (JSON, SI units),
    ``status`` ('pending' | 'ok' | 'failed' | 'unstable' | 'timeout'), ``cost``, ``dtw_xy`` [m],
    ``dtw_theta`` [rad], ``transit_time`` [s], ``seed`` (a screen's: the placement seed, 0 for the
    nominal placement), ``wall_time`` [s], ``asked_at`` and
    ``finished_at`` (Unix time [s]), ``run_file`` (trajectory file, relative to the study
    folder), ``details`` (JSON: validation criteria, diagnostics; a screen's run at a seeded
    placement: ``rotation``, its net rotation [rad]).

A batch is written as ``pending`` rows before any of it runs; each result replaces its row in one
transaction the moment it arrives. A study killed at any point therefore finds on restart every
finished evaluation (never simulated again) and exactly the pending ones to run.

A write that fails (a full disk: SQLITE_FULL, a read-only file) is rolled back, leaving the
store as it was before it, and raised as a `ParcelfitError` saying so.

A new store is created under a temporary name and renamed once its schema is written, so an
existing ``study.sqlite`` always has one: an empty (0-byte) or unreadable file is damaged and
refused, never silently restarted. ``readonly=True`` (``status``, ``report``) opens the file with
SQLite's ``mode=ro`` and never writes to it.

Stores written by earlier versions open as they are: a record's missing fields take their
defaults, and a study record without the optimiser (written before it was kept) reads as the
default GP with ``OptimizerRecord.recorded`` False, so that readers can say so.
"""

from __future__ import annotations

import errno
import json
import os
import sqlite3
import time
import urllib.parse
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    SerializerFunctionWrapHandler,
    model_serializer,
    model_validator,
)

from parcelfit.errors import ParcelfitError, os_error
from parcelfit.study.details import EvaluationDetails

STORE_FILE = "study.sqlite"  # a calibration study's store, in its folder

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS evaluations (
    id INTEGER PRIMARY KEY,
    kind TEXT NOT NULL CHECK (kind IN ('fit', 'validation', 'screen', 'twin', 'precision')),
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
    details: EvaluationDetails


# -- typed meta records ------------------------------------------------------------------------


def _number(doc: Mapping[str, Any], key: str, default: Any) -> Any:
    value = doc.get(key)
    return default if value is None else value


class OptimizerRecord(BaseModel):
    """The optimiser a study ran: the sampler's name (gp, published, tpe) and, for a GP sampler,
    its `BOSettings` fields as used (None for a sampler without a GP). ``recorded`` is False
    when the store predates the record: the values are then the defaults (the default GP)."""

    model_config = ConfigDict(frozen=True)

    sampler: str = "gp"
    settings: dict[str, Any] | None = None
    recorded: bool = True

    def to_json(self) -> dict[str, Any]:
        """As JSON (the study record stores the fields under its own keys, see `StudyRecord`)."""
        return self.model_dump()

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> OptimizerRecord:
        """Read `to_json`'s form."""
        return cls.model_validate(dict(doc))

    @property
    def note(self) -> str | None:
        """A sentence for readers when the settings are not the study's own (else None)."""
        if not self.recorded:
            return (
                "the study's store was written by an earlier parcelfit that did not record the "
                "optimiser settings: the default GP settings are used in their place"
            )
        if self.settings is None:
            return (
                f"the {self.sampler} optimiser has no GP: the surrogate is the GP with the "
                "default settings"
            )
        return None


class StudyRecord(BaseModel):
    """What a study is: its name, fitted parameters with bounds (SI) and log flags, batch size,
    seed, fitting and validation speed settings, and the optimiser as it ran (stored as
    ``sampler`` and ``bo_settings`` after the other fields)."""

    model_config = ConfigDict(frozen=True)

    name: str
    parameters: tuple[str, ...]
    bounds: tuple[tuple[float, float], ...]
    log: tuple[bool, ...]
    batch_size: int = 4
    seed: int = 0
    fit_setting: int = 1
    validation_setting: int | None = None
    optimizer: OptimizerRecord = Field(default_factory=lambda: OptimizerRecord(recorded=False))

    @model_validator(mode="before")
    @classmethod
    def _read_stored_form(cls, doc: Any) -> Any:
        """The stored form, tolerating records of earlier versions (missing or null keys:
        defaults; no name: "?"; no ``sampler``: the optimiser was not recorded)."""
        if not isinstance(doc, Mapping) or "optimizer" in doc:
            return doc
        names = tuple(str(n) for n in doc.get("parameters") or ())
        if "sampler" in doc:
            optimizer = OptimizerRecord(
                sampler=str(doc["sampler"]), settings=doc.get("bo_settings"), recorded=True
            )
        else:
            optimizer = OptimizerRecord(recorded=False)
        return {
            "name": str(doc.get("name") or "?"),
            "parameters": names,
            "bounds": doc.get("bounds") or (),
            "log": doc.get("log") or [False] * len(names),
            "batch_size": _number(doc, "batch_size", 4),
            "seed": _number(doc, "seed", 0),
            "fit_setting": _number(doc, "fit_setting", 1),
            "validation_setting": doc.get("validation_setting"),
            "optimizer": optimizer,
        }

    @model_serializer(mode="wrap")
    def _write_stored_form(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        """The fields, the optimiser's as ``sampler`` and ``bo_settings``."""
        out = handler(self)
        out.pop("optimizer", None)
        return {**out, "sampler": self.optimizer.sampler, "bo_settings": self.optimizer.settings}

    def to_json(self) -> dict[str, Any]:
        """The stored form (JSON-ready; bounds in SI)."""
        return self.model_dump()

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> StudyRecord:
        """Read a stored record, tolerating those of earlier versions."""
        return cls.model_validate(dict(doc))


class SourceRecord(BaseModel):
    """Where a study came from, so a report can find its file and data again (absolute paths
    as strings, None where unknown)."""

    model_config = ConfigDict(frozen=True, extra="ignore")

    study_file: str | None = None
    dataset: str | None = None
    rig: str | None = None
    consignment: str | None = None

    def to_json(self) -> dict[str, Any]:
        """The stored form: every field, None where unknown."""
        return self.model_dump()

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> SourceRecord:
        """Read a stored record (missing keys: None)."""
        return cls.model_validate(dict(doc))


class RecommendedRecord(BaseModel):
    """The parameters a study validates and reports (SI, fitted ones only) and their cost."""

    model_config = ConfigDict(frozen=True, extra="ignore")

    params: dict[str, float]
    cost: float

    def to_json(self) -> dict[str, Any]:
        """The stored form."""
        return self.model_dump()

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> RecommendedRecord:
        """Read a stored record."""
        return cls.model_validate(dict(doc))


def _full(exc: sqlite3.Error) -> bool:
    """Whether SQLite failed because the disk (or quota) is full (SQLITE_FULL)."""
    return getattr(exc, "sqlite_errorcode", None) == sqlite3.SQLITE_FULL or "disk is full" in str(
        exc
    )


class CaseRecord(BaseModel):
    """One test case of a study as the store and the results keep it: its label ``case``,
    ``role`` (fit, validation or transfer), ``weight`` in the cost, ``dataset`` folder,
    ``reference_run``, the acceptance ``threshold`` of a fitted case [-] and ``transit`` (what
    the transit-time adjustment did, in words); None where not recorded. Its stored form keeps
    exactly the keys it was given (a store of an earlier version lacks ``transit``)."""

    model_config = ConfigDict(frozen=True, extra="ignore")

    case: str
    role: str
    weight: float = 1.0
    dataset: str | None = None
    reference_run: str | None = None
    threshold: float | None = None
    transit: str | None = None

    def to_json(self) -> dict[str, Any]:
        """The stored form: the keys it was read or made with."""
        return self.model_dump(exclude_unset=True)

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> CaseRecord:
        """Read the stored form (`to_json`)."""
        return cls.model_validate(dict(doc))


_RECORDS = ("study", "source", "recommended", "cases")  # meta keys read and written as records only
_R = TypeVar("_R")


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
        if _full(exc):
            full = OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self.path))
            return os_error(full, resumes=True)  # type: ignore[return-value]
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

    def _write_error(self, exc: sqlite3.OperationalError) -> BaseException:
        """What a failed write raises: a read-only or full store as a `ParcelfitError` that
        says the results are intact, anything else as it is."""
        if "readonly" in str(exc) or _full(exc):
            return self._error(exc)
        return exc

    @contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        """One transaction: committed when the block ends, rolled back (the store as before)
        when it or the commit fails; a full disk or read-only store is a `ParcelfitError`."""
        if self.readonly:
            raise ParcelfitError("this store was opened read-only", file=self.path)
        try:
            self._db.execute("BEGIN IMMEDIATE")
        except sqlite3.OperationalError as exc:
            raise self._write_error(exc) from exc
        try:
            yield self._db
            self._db.execute("COMMIT")  # a full disk may fail here, the transaction still open
        except BaseException as exc:
            with suppress(sqlite3.Error):  # nothing to roll back if SQLite already did
                self._db.execute("ROLLBACK")
            if isinstance(exc, sqlite3.OperationalError):
                raise self._write_error(exc) from exc
            raise

    # -- meta -------------------------------------------------------------------------------
    def _read_meta(self, key: str) -> Any:
        row = self._db.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        return None if row is None else json.loads(row[0])

    def _write_meta(self, key: str, value: Any) -> None:
        with self._transaction() as db:
            db.execute(
                "INSERT OR REPLACE INTO meta (key, value) VALUES (?, ?)", (key, json.dumps(value))
            )

    def get_meta(self, key: str) -> Any:
        """A plain study-level value (None if absent); the records have their own readers."""
        if key in _RECORDS:
            raise ParcelfitError(f"the {key!r} record is read with read_{key}()")
        return self._read_meta(key)

    def set_meta(self, key: str, value: Any) -> None:
        """Store a plain study-level value (JSON-serialisable); the records have their own
        writers."""
        if key in _RECORDS:
            raise ParcelfitError(f"the {key!r} record is written with write_{key}()")
        self._write_meta(key, value)

    def claim_meta(self, key: str, value: Any) -> bool:
        """Store ``value`` under ``key`` when nothing is stored there; whether what is stored is
        ``value`` (compared as JSON): the check by which a resumed job refuses other inputs."""
        known = self.get_meta(key)
        if known is None:
            self.set_meta(key, value)
            return True
        return bool(json.loads(json.dumps(known)) == json.loads(json.dumps(value)))

    def _record(self, key: str, read: Callable[[Mapping[str, Any]], _R]) -> _R | None:
        doc = self._read_meta(key)
        if doc is None:
            return None
        try:
            return read(doc)
        except (TypeError, ValueError, KeyError, AttributeError) as exc:
            raise ParcelfitError(
                f"the study database's {key!r} record is damaged ({exc})",
                file=self.path,
                fix="restore the database from a backup",
            ) from None

    def read_study(self) -> StudyRecord | None:
        """The study record (None before a calibration wrote one)."""
        return self._record("study", StudyRecord.from_json)

    def write_study(self, record: StudyRecord) -> None:
        """Store the study record."""
        self._write_meta("study", record.to_json())

    def read_source(self) -> SourceRecord | None:
        """Where the study came from (None if never written)."""
        return self._record("source", SourceRecord.from_json)

    def write_source(self, record: SourceRecord) -> None:
        """Store where the study came from."""
        self._write_meta("source", record.to_json())

    def read_recommended(self) -> RecommendedRecord | None:
        """The recommended parameters (None until the study stops)."""
        return self._record("recommended", RecommendedRecord.from_json)

    def write_recommended(self, record: RecommendedRecord) -> None:
        """Store the recommended parameters."""
        self._write_meta("recommended", record.to_json())

    def read_cases(self) -> list[CaseRecord] | None:
        """The study's test cases (None before a calibration wrote them)."""
        return self._record("cases", lambda doc: [CaseRecord.from_json(c) for c in doc])

    def write_cases(self, cases: Sequence[CaseRecord]) -> None:
        """Store the study's test cases."""
        self._write_meta("cases", [c.to_json() for c in cases])

    # -- evaluations ------------------------------------------------------------------------
    def add_pending(
        self,
        kind: str,
        iteration: int,
        batch: Sequence[Mapping[str, float]],
        speed_setting: int,
        seeds: Sequence[int | None],
        *,
        first_slot: int = 0,
        details: EvaluationDetails | None = None,
    ) -> list[int]:
        """Record a batch as pending (one transaction), in the slots from ``first_slot`` on,
        each with ``details`` if given (what identifies it before it is run: its test case);
        returns the row ids in batch order."""
        now = time.time()
        ids = []
        stored = None if details is None else details.dumps()
        with self._transaction() as db:
            for slot, (params, seed) in enumerate(zip(batch, seeds, strict=True), first_slot):
                cur = db.execute(
                    "INSERT INTO evaluations (kind, iteration, slot, speed_setting, params, status, "
                    "seed, asked_at, details) VALUES (?, ?, ?, ?, ?, 'pending', ?, ?, ?)",
                    (
                        kind,
                        iteration,
                        slot,
                        speed_setting,
                        json.dumps(dict(params)),
                        seed,
                        now,
                        stored,
                    ),
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
        details: EvaluationDetails | None = None,
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
                    (details or EvaluationDetails()).dumps(),
                    row_id,
                ),
            )
            if cur.rowcount != 1:
                raise ParcelfitError(f"no evaluation with id {row_id} in {self.path}")

    def reopen(self, row_ids: Sequence[int], *, keep_case: bool = False) -> None:
        """Make finished evaluations pending again (one transaction), so they run on resume;
        with ``keep_case`` their details keep their test case (and nothing else)."""
        with self._transaction() as db:
            for row_id in row_ids:
                details = None
                if keep_case:
                    row = db.execute(
                        "SELECT details FROM evaluations WHERE id = ?", (row_id,)
                    ).fetchone()
                    case = EvaluationDetails.parse(row[0] if row else None, self.path).case
                    details = None if case is None else EvaluationDetails(case=case).dumps()
                db.execute(
                    "UPDATE evaluations SET status = 'pending', cost = NULL, dtw_xy = NULL, "
                    "dtw_theta = NULL, transit_time = NULL, wall_time = NULL, finished_at = NULL, "
                    "run_file = NULL, details = ? WHERE id = ?",
                    (details, row_id),
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
                    details=EvaluationDetails.parse(r[16], self.path),
                )
            )
        return out


def finished_count(path: str | Path, kind: str) -> int:
    """How many evaluations of ``kind`` the store at ``path`` holds finished (not pending); 0
    where there is no store yet. Opens the store read-only: safe beside a running study."""
    path = Path(path)
    if not path.is_file():
        return 0
    store = Store(path, readonly=True)
    try:
        return sum(e.status != "pending" for e in store.evaluations(kind))
    finally:
        store.close()
