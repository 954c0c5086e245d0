"""The real runs' scatter runs, shared between the predictions of one study.

Every prediction of a study simulates the same runs to estimate the real runs' own scatter
(`parcelfit.study.run_scatter`): the recommended parameters at the same seeded placements, with
the same drive deviation, on every fitted and validation case of the study. They do not depend
on the design predicted. A prediction therefore first takes them from another prediction's store
of the same study (the folders ``predict-*`` in the study folder, and the other folders beside
its own output folder) and simulates only those it finds nowhere.

A finished run is taken over only where it is the same simulation: the other store's ``scatter``
record equals this one's (the study folder, the study file's fingerprint, the case labels in
order, the drive deviation, the versions of parcelfit and MuJoCo and, for a ``python`` backend,
a hash of its factory's module file), and its row has the same case index (the store's
``iteration``), slot, parameters, speed setting and placement seed, and ended ok. A store
advertises the record only if it claimed it before any of its scatter runs finished (so every
one of them was simulated under it). The copy keeps the run's own wall time; the
``scatter_reused`` record lists the ids of the rows taken (written before they are finished,
and pruned of any still pending on a resume, so a crash cannot hide a copied run) and the
folders they came from.

What no record holds: a rig, consignment or solver file edited between two predictions under
the same name, and a change of parcelfit's code without a change of its version (as with the
calibration's own store, which a resume also continues). Reading another store, SQLite leaves
its ``-wal`` and ``-shm`` files beside it, as any reader of a parcelfit store does.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import sqlite3
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

from parcelfit import __version__
from parcelfit.errors import ParcelfitError
from parcelfit.study.store import Evaluation, Store
from parcelfit.study.studyfile import Study

SCATTER_RECORD = "scatter"  # what identifies a store's scatter runs beyond their rows
REUSED_RECORD = "scatter_reused"  # how many scatter rows were taken over, and from where
STORE_NAME = "predict.sqlite"


@dataclass(frozen=True)
class Reused:
    """Scatter runs taken over from other predictions by one call: the row count and the
    folders they came from."""

    rows: int
    sources: tuple[str, ...]


def _factory_hash(factory: str | None) -> str | None:
    """A hash of the module file a python backend's ``factory`` (module:callable) comes from
    (None where there is none or it cannot be found)."""
    if not factory:
        return None
    try:
        spec = importlib.util.find_spec(str(factory).partition(":")[0])
        origin = None if spec is None else spec.origin
        if origin is None or not Path(origin).is_file():
            return None
        return hashlib.sha256(Path(origin).read_bytes()).hexdigest()[:16]
    except (ImportError, ValueError, OSError):
        return None


def _mujoco_version() -> str | None:
    try:
        return version("mujoco")
    except PackageNotFoundError:
        return None


def scatter_record(
    study_dir: Path, study: Study, cases: Sequence[str], speed_deviation: float
) -> dict[str, Any]:
    """What a store's scatter runs share beyond their rows: the study folder (absolute), its
    file's fingerprint, the case labels in the order of the rows' ``iteration`` (from 1), the
    drive deviation [-], the versions of parcelfit and MuJoCo and, for a python backend, its
    factory module's hash."""
    record: dict[str, Any] = {
        "study": str(Path(study_dir).resolve()),
        "fingerprint": study.fingerprint,
        "cases": list(cases),
        "speed_deviation": float(speed_deviation),
        "parcelfit": __version__,
        "mujoco": _mujoco_version(),
    }
    if study.simulator.backend == "python":
        record["factory"] = _factory_hash(study.simulator.factory)
    return record


def claim_scatter_record(store: Store, record: dict[str, Any]) -> bool:
    """Give ``store`` the scatter ``record`` (so that other predictions may take its runs) if it
    holds it already, or holds none and none of its scatter runs has finished yet; whether it
    holds it now."""
    held = store.get_meta(SCATTER_RECORD)
    if held is not None:
        return bool(held == json.loads(json.dumps(record)))
    if any(e.iteration > 0 and e.status != "pending" for e in store.evaluations("screen")):
        return False  # runs finished before the record existed: not vouched for
    return store.claim_meta(SCATTER_RECORD, record)


def _key(e: Evaluation) -> tuple[int, int, str, int, int | None]:
    return (e.iteration, e.slot, json.dumps(e.params, sort_keys=True), e.speed_setting, e.seed)


def candidate_stores(study_dir: Path, out_dir: Path) -> list[Path]:
    """The prediction stores that may hold this study's scatter runs: those of the study
    folder's ``predict-*`` folders and of the folders beside ``out_dir``, without ``out_dir``'s
    own, each once, sorted; a folder that cannot be read is passed over."""
    own = (Path(out_dir) / STORE_NAME).resolve()
    found: set[Path] = set()
    for pattern_dir, pattern in ((Path(study_dir), "predict-*"), (Path(out_dir).parent, "*")):
        try:
            folders = sorted(pattern_dir.glob(pattern)) if pattern_dir.is_dir() else []
        except OSError:
            continue
        for folder in folders:
            path = folder / STORE_NAME
            try:
                if path.is_file() and path.resolve() != own:
                    found.add(path.resolve())
            except OSError:  # a folder of another user's, say
                continue
    return sorted(found)


def _finished_scatter(path: Path, record: dict[str, Any]) -> dict[tuple[Any, ...], Evaluation]:
    """The ok scatter rows of the store at ``path`` by their key, if its scatter record equals
    ``record``; none if it does not, or the store cannot be read (a damaged or foreign file is
    passed over: it only means these runs are simulated again)."""
    try:
        other = Store(path, readonly=True)
    except (ParcelfitError, sqlite3.Error, OSError):
        return {}
    try:
        if other.get_meta(SCATTER_RECORD) != json.loads(json.dumps(record)):
            return {}
        return {
            _key(e): e for e in other.evaluations("screen") if e.iteration > 0 and e.status == "ok"
        }
    except (ParcelfitError, sqlite3.Error, ValueError):
        return {}
    finally:
        other.close()


def reuse_scatter_runs(store: Store, record: dict[str, Any], sources: Iterable[Path]) -> Reused:
    """Finish ``store``'s pending scatter rows (``iteration`` >= 1) with the same simulations
    finished ok in the stores at ``sources`` whose scatter record is ``record`` (module
    docstring), each in its own transaction, listed in the store's ``scatter_reused`` record
    before it is finished."""
    pending = {
        _key(e): e for e in store.evaluations("screen") if e.iteration > 0 and e.status == "pending"
    }
    before = store.get_meta(REUSED_RECORD) or {"ids": [], "from": []}
    # listed, then not finished (a crash while copying): simulated here unless copied again
    ids = {int(i) for i in before["ids"]} - {e.id for e in pending.values()}
    sources_used = set(before["from"])

    def write_reused() -> None:
        store.set_meta(
            REUSED_RECORD, {"rows": len(ids), "ids": sorted(ids), "from": sorted(sources_used)}
        )

    if len(ids) != len(before["ids"]):
        write_reused()
    taken = 0
    used: list[str] = []
    for path in sources:
        if not pending:
            break
        finished = _finished_scatter(path, record)
        hits = [k for k in pending if k in finished]
        if not hits:
            continue
        used.append(path.parent.name)
        ids |= {pending[k].id for k in hits}
        sources_used.add(str(path.parent))
        write_reused()  # before the copies finish, so that a crash cannot hide one
        for k in hits:
            src, row = finished[k], pending.pop(k)
            store.finish(
                row.id,
                status=src.status,
                transit_time=src.transit_time,
                wall_time=src.wall_time,
                details=src.details,
            )
        taken += len(hits)
    return Reused(taken, tuple(used))


def reused_ids(store: Store) -> set[int]:
    """The ids of ``store``'s scatter rows taken over from other predictions."""
    record = store.get_meta(REUSED_RECORD)
    return set() if not record else {int(i) for i in record["ids"]}
