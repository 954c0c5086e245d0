"""The real runs' scatter runs, shared between the predictions of one study.

Every prediction of a study simulates the same runs to estimate the real runs' own scatter
(`parcelfit.study.run_scatter`): the recommended parameters at the same seeded placements, with
the same drive deviation, on every fitted and validation case of the study. They do not depend
on the design predicted. A prediction therefore first takes them from another prediction's store
of the same study (the folders ``predict-*`` in the study folder, and the other folders beside
its own output folder) and simulates only those it finds nowhere.

A finished run is taken over only where it is the same simulation: the other store's ``scatter``
record (the study folder, the study file's fingerprint, the study's case labels in order and the
drive deviation) equals this one's, and its row has the same case index (the store's
``iteration``), slot, parameters, speed setting and placement seed, and ended ok. The copy keeps
the run's own wall time; the ``scatter_reused`` record counts the rows taken, lists their ids
and names the folders they came from. A simulation is deterministic for these inputs, so a run taken over is
the run this prediction would have made. What no record holds: a rig or consignment file edited
between two predictions under the same name (as with the calibration's own store).
"""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

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


def scatter_record(
    study_dir: Path, study: Study, cases: Sequence[str], speed_deviation: float
) -> dict[str, Any]:
    """What a store's scatter runs share beyond their rows: the study folder (absolute), its
    file's fingerprint, the case labels in the order of the rows' ``iteration`` (from 1) and the
    drive deviation [-]."""
    return {
        "study": str(Path(study_dir).resolve()),
        "fingerprint": study.fingerprint,
        "cases": list(cases),
        "speed_deviation": float(speed_deviation),
    }


def _key(e: Evaluation) -> tuple[int, int, str, int, int | None]:
    return (e.iteration, e.slot, json.dumps(e.params, sort_keys=True), e.speed_setting, e.seed)


def candidate_stores(study_dir: Path, out_dir: Path) -> list[Path]:
    """The prediction stores that may hold this study's scatter runs: those of the study
    folder's ``predict-*`` folders and of the folders beside ``out_dir``, without ``out_dir``'s
    own, each once, sorted."""
    own = (Path(out_dir) / STORE_NAME).resolve()
    found: set[Path] = set()
    for pattern_dir, pattern in ((Path(study_dir), "predict-*"), (Path(out_dir).parent, "*")):
        if not pattern_dir.is_dir():
            continue
        for folder in pattern_dir.glob(pattern):
            path = folder / STORE_NAME
            if path.is_file() and path.resolve() != own:
                found.add(path.resolve())
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
    except (ParcelfitError, sqlite3.Error):
        return {}
    finally:
        other.close()


def reuse_scatter_runs(store: Store, record: dict[str, Any], sources: Iterable[Path]) -> Reused:
    """Finish ``store``'s pending scatter rows (``iteration`` >= 1) with the same simulations
    finished ok in the stores at ``sources`` (module docstring), each in its own transaction;
    add them to the store's ``scatter_reused`` record. ``store`` must hold ``record``."""
    if store.get_meta(SCATTER_RECORD) != json.loads(json.dumps(record)):
        return Reused(0, ())
    pending = {
        _key(e): e for e in store.evaluations("screen") if e.iteration > 0 and e.status == "pending"
    }
    taken: list[int] = []
    used: list[str] = []
    for path in sources:
        if not pending:
            break
        finished = _finished_scatter(path, record)
        hits = [k for k in pending if k in finished]
        for k in hits:
            src, row = finished[k], pending.pop(k)
            store.finish(
                row.id,
                status=src.status,
                transit_time=src.transit_time,
                wall_time=src.wall_time,
                details=src.details,
            )
            taken.append(row.id)
        if hits:
            used.append(path.parent.name)
    if taken:
        before = store.get_meta(REUSED_RECORD) or {"ids": [], "from": []}
        ids = sorted({*before["ids"], *taken})
        store.set_meta(
            REUSED_RECORD,
            {"rows": len(ids), "ids": ids, "from": sorted({*before["from"], *used})},
        )
    return Reused(len(taken), tuple(used))


def reused_ids(store: Store) -> set[int]:
    """The ids of ``store``'s scatter rows taken over from other predictions."""
    record = store.get_meta(REUSED_RECORD)
    return set() if not record else {int(i) for i in record["ids"]}
