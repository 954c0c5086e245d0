"""Simulations shared between the predictions of one study.

A prediction (`parcelfit.study.predict`) simulates three kinds of runs; two of them recur in
other predictions of the same study, and a prediction first takes those from another
prediction's store (the folders ``predict-*`` in the study folder, and the other folders beside
its own output folder) and simulates only those it finds nowhere:

* **the real runs' scatter runs** (store rows with ``iteration`` >= 1): the recommended
  parameters at the same seeded placements, with the same drive deviation, on every fitted and
  validation case of the study (`parcelfit.study.run_scatter`). They do not depend on the
  design predicted, so every prediction of the study with the same seed shares them.
* **the design's own runs** (``iteration`` 0: the drawn parameter sets at the placements;
  -1 and -2: the numerical error's on the model and the refined model,
  `parcelfit.study.numerical_error`). They depend on the design, so they are shared only
  between predictions of the same design: most often the numerical error's, which do not
  depend on ``--sets`` or ``--placements``, when a design is predicted again with more sets.

A finished run is taken over only where it is the same simulation: the other store's record of
that kind equals this one's, and its row has the same key and ended ok. The ``scatter`` record
holds the study folder, the study file's fingerprint, the case labels in order, the drive
deviation, the versions of parcelfit and MuJoCo and, for a ``python`` backend, a hash of its
factory's module file; a scatter row's key is its case index (the store's ``iteration``),
slot, parameters, speed setting and placement seed. The
``design_runs`` record holds the same but the cases, the design (its label, the rig and
consignment as given and a hash of each one's file where it is a file: a rig file edited
between two predictions is another design) and the study's refinement (which its fingerprint
leaves out); a design row's key is its ``iteration``, parameters, speed setting and placement
seed, not its slot: with other ``--sets`` a set both draws hold sits at another slot. (Other
``--placements`` draw other placement seeds, and other ``--sets`` mostly other sets, so a
design's own runs recur mainly when the sets and placements are the same and another input,
such as ``--scatter-runs``, differs; its numerical error's recur whenever the seed does.) A
store advertises a record only if it claimed it before any run of that kind finished, and a
store resumed under another record while runs of that kind are still pending has its record
withdrawn: every run a record vouches for was simulated under it.
The copy keeps the run's own wall time; the records ``scatter_reused`` and ``design_reused``
list the ids of the rows taken (written before they are finished, and pruned of any still
pending on a resume, so a crash cannot hide a copied run) and the folders they came from.

What no record holds: a bundled rig or consignment, or a file a rig or consignment file does
not contain itself, changed between two predictions without a change of parcelfit's version; an
external solver's description file (its command and template) or its program changed under
the same path; the modules other than the factory's own, and the environment, that a python
backend reads; a change of parcelfit's code without a change of its version (as with the
calibration's own store, which a resume also continues).
Reading another store, SQLite leaves its ``-wal`` and ``-shm`` files beside it, as any reader of
a parcelfit store does.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import sqlite3
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

from parcelfit import __version__
from parcelfit.errors import ParcelfitError
from parcelfit.study.plausible import Design
from parcelfit.study.store import Evaluation, Store
from parcelfit.study.studyfile import Study

STORE_NAME = "predict.sqlite"


def _params(e: Evaluation) -> str:
    return json.dumps(e.params, sort_keys=True)


@dataclass(frozen=True)
class Kind:
    """One kind of shared run: the meta keys of its ``record`` and of its ``reused`` rows, which
    rows of a store are of this kind, and the key under which two rows are the same simulation
    (module docstring)."""

    record: str
    reused: str
    rows: Callable[[Evaluation], bool]
    key: Callable[[Evaluation], tuple[Any, ...]]


SCATTER = Kind(
    "scatter",
    "scatter_reused",
    lambda e: e.iteration > 0,
    lambda e: (e.iteration, e.slot, _params(e), e.speed_setting, e.seed),
)
DESIGN = Kind(
    "design_runs",
    "design_reused",
    lambda e: e.iteration <= 0,
    lambda e: (e.iteration, _params(e), e.speed_setting, e.seed),
)
KINDS = (SCATTER, DESIGN)
WITHDRAWN = {"withdrawn": "resumed under another record"}  # a record that matches none
SCATTER_RECORD, REUSED_RECORD = SCATTER.record, SCATTER.reused  # the scatter runs' meta keys


@dataclass(frozen=True)
class Reused:
    """Runs taken over from other predictions by one call: the row count and the folders they
    came from."""

    rows: int
    sources: tuple[str, ...]


def _file_hash(path: str | Path) -> str | None:
    """A hash of the file at ``path`` (None where it cannot be read)."""
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]
    except OSError:
        return None


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
        return _file_hash(origin)
    except (ImportError, ValueError):
        return None


def _mujoco_version() -> str | None:
    try:
        return version("mujoco")
    except PackageNotFoundError:
        return None


def _common_record(study_dir: Path, study: Study, speed_deviation: float) -> dict[str, Any]:
    record: dict[str, Any] = {
        "study": str(Path(study_dir).resolve()),
        "fingerprint": study.fingerprint,
        "speed_deviation": float(speed_deviation),
        "parcelfit": __version__,
        "mujoco": _mujoco_version(),
    }
    if study.simulator.backend == "python":
        record["factory"] = _factory_hash(study.simulator.factory)
    return record


def scatter_record(
    study_dir: Path, study: Study, cases: Sequence[str], speed_deviation: float
) -> dict[str, Any]:
    """What a store's scatter runs share beyond their rows: the study folder (absolute), its
    file's fingerprint, the case labels in the order of the rows' ``iteration`` (from 1), the
    drive deviation [-], the versions of parcelfit and MuJoCo and, for a python backend, its
    factory module's hash."""
    return {**_common_record(study_dir, study, speed_deviation), "cases": list(cases)}


def design_record(
    study_dir: Path, study: Study, design: Design, speed_deviation: float
) -> dict[str, Any]:
    """What a store's design runs (its own and the numerical error's) share beyond their rows:
    the scatter record's entries but the cases, the design's label, its rig and consignment as
    given and a hash of each one's file (None for a bundled name), and the study's
    refinement (the numerical error's refined runs')."""
    files = {}
    for name, given in (("rig", design.rig), ("consignment", design.consignment)):
        is_file = given.lower().endswith((".yaml", ".yml"))
        files[name] = {"given": given, "hash": _file_hash(given) if is_file else None}
    return {
        **_common_record(study_dir, study, speed_deviation),
        "design": design.label,
        **files,
        "refinement": study.refinement,  # the refined runs' (not in the study's fingerprint)
    }


def claim_record(store: Store, kind: Kind, record: dict[str, Any]) -> bool:
    """Give ``store`` the ``record`` of ``kind`` (so that other predictions may take its runs
    of that kind) if it holds it already, or holds none and none of its runs of that kind has
    finished yet; whether it holds it now. A store holding another record with runs of that
    kind still pending has it withdrawn (it then matches no record)."""
    held = store.get_meta(kind.record)
    rows = [e for e in store.evaluations("screen") if kind.rows(e)]
    if held is not None:
        if held == json.loads(json.dumps(record)):
            return True
        if held != WITHDRAWN and any(e.status == "pending" for e in rows):
            # resumed under another record (a new version, a file edited): the runs still to
            # come are not what the held record vouches for, so it vouches for none
            store.set_meta(kind.record, WITHDRAWN)
        return False
    if any(e.status != "pending" for e in rows):
        return False  # runs finished before the record existed: not vouched for
    return store.claim_meta(kind.record, record)


def candidate_stores(study_dir: Path, out_dir: Path) -> list[Path]:
    """The prediction stores that may hold this study's runs: those of the study folder's
    ``predict-*`` folders and of the folders beside ``out_dir``, without ``out_dir``'s own,
    each once, sorted; a folder that cannot be read is passed over."""
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


def _finished(path: Path, kind: Kind, record: dict[str, Any]) -> dict[tuple[Any, ...], Evaluation]:
    """The ok rows of ``kind`` of the store at ``path`` by their key, if its record of that
    kind equals ``record``; none if it does not, or the store cannot be read (a damaged or
    foreign file is passed over: it only means these runs are simulated again)."""
    try:
        other = Store(path, readonly=True)
    except (ParcelfitError, sqlite3.Error, OSError):
        return {}
    try:
        if other.get_meta(kind.record) != json.loads(json.dumps(record)):
            return {}
        return {
            kind.key(e): e for e in other.evaluations("screen") if kind.rows(e) and e.status == "ok"
        }
    except (ParcelfitError, sqlite3.Error, ValueError):
        return {}
    finally:
        other.close()


def reuse_runs(store: Store, kind: Kind, record: dict[str, Any], sources: Iterable[Path]) -> Reused:
    """Finish ``store``'s pending rows of ``kind`` with the same simulations finished ok in the
    stores at ``sources`` whose record of that kind is ``record`` (module docstring), each in
    its own transaction, listed in the store's record of reused rows before it is finished."""
    waiting = [e for e in store.evaluations("screen") if kind.rows(e) and e.status == "pending"]
    pending: dict[tuple[Any, ...], Evaluation] = {}
    for e in waiting:
        pending.setdefault(kind.key(e), e)  # a set drawn twice: its second row runs here
    before = store.get_meta(kind.reused) or {"ids": [], "from": []}
    # listed, then not finished (a crash while copying): simulated here unless copied again
    ids = {int(i) for i in before["ids"]} - {e.id for e in waiting}
    sources_used = set(before["from"])

    def write_reused() -> None:
        store.set_meta(
            kind.reused, {"rows": len(ids), "ids": sorted(ids), "from": sorted(sources_used)}
        )

    if len(ids) != len(before["ids"]):
        write_reused()
    taken = 0
    used: list[str] = []
    for path in sources:
        if not pending:
            break
        finished = _finished(path, kind, record)
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


def reused_ids(store: Store, kinds: Sequence[Kind] = KINDS) -> set[int]:
    """The ids of ``store``'s rows of ``kinds`` (default: every kind) taken over from other
    predictions."""
    out: set[int] = set()
    for kind in kinds:
        record = store.get_meta(kind.reused)
        if record:
            out |= {int(i) for i in record["ids"]}
    return out
