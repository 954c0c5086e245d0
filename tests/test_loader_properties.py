"""Property-based tests of the loaders of the files a person writes (issue 51: no input hangs or
breaks parcelfit): study, screen, rig, consignment, tag map and twin spec files, and datasets
(``dataset.yaml`` with its run files). Valid documents (the test bases of test_config_files,
bundled rigs and consignments, the examples) are mutated (keys deleted, values replaced by
random YAML scalars, lists and mappings, huge, negative and non-finite numbers, Unicode junk,
keys written twice, aliases, alias bombs, deep nesting, bytes that are not UTF-8, truncation)
and each must load into its object or stop with a `ParcelfitError` naming a file, on one line,
within the time limit; any other exception is a bug in the loader.

Hypothesis: a bounded number of examples per loader (the file runs in well under a minute on one
core), a deadline per example and, in CI (``CI=true``), derandomized for determinism."""

from __future__ import annotations

import contextlib
import copy
import math
import os
import shutil
import signal
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from parcelfit import ParcelfitError
from parcelfit.config import load_yaml
from parcelfit.runs import Dataset, load_dataset
from parcelfit.sim.mujoco import load_consignment, load_rig
from parcelfit.sim.mujoco.consignment import Consignment
from parcelfit.sim.mujoco.rig import Rig
from parcelfit.study.screening import Screen, load_screen
from parcelfit.study.studyfile import Study, load_study
from parcelfit.synth import TwinSpec, load_twin_spec
from parcelfit.tracking import load_tag_map
from parcelfit.tracking.tagmap import TagMap

from .fake_sim import write_reference_dataset
from .helpers import ROOT
from .test_config_files import CONSIGNMENT, RIG, SCREEN, STUDY, TAGS, TWIN

CI = os.environ.get("CI") == "true"
# examples per loader and test (13 tests of 25 take about 10 s on one core); LOADER_EXAMPLES=500
# searches deeper, e.g. after a change to a loader
EXAMPLES = int(os.environ.get("LOADER_EXAMPLES", "25"))
DEADLINE_MS = 2000  # what Hypothesis allows one example
HANG_S = 20  # an example still running after this is a hang: the test fails instead of waiting
LOADER_SETTINGS = settings(
    max_examples=EXAMPLES,
    deadline=DEADLINE_MS,
    derandomize=CI,
    database=None if CI else settings.default.database,
    suppress_health_check=[
        HealthCheck.function_scoped_fixture,  # tmp_path: each example overwrites its files
        HealthCheck.too_slow,
        HealthCheck.data_too_large,
    ],
)

SRC = ROOT / "src" / "parcelfit"


def _bundled(*relative: str) -> dict[str, Any]:
    doc = load_yaml(SRC.joinpath(*relative))
    assert isinstance(doc, dict)
    return doc


# kind: (loader, type of what it returns, valid documents to start from)
LOADERS: dict[str, tuple[Callable[[Path], Any], type, list[dict[str, Any]]]] = {
    "study": (load_study, Study, [STUDY, load_yaml(ROOT / "examples" / "e3-kpbw" / "study.yaml")]),
    "screen": (
        load_screen,
        Screen,
        [SCREEN, load_yaml(ROOT / "examples" / "e3-kpbw" / "screen.yaml")],
    ),
    "twin": (
        load_twin_spec,
        TwinSpec,
        [TWIN, _bundled("data", "examples", "twin-spec.yaml")],
    ),
    "tags": (load_tag_map, TagMap, [TAGS]),
    "rig": (
        load_rig,
        Rig,
        [
            RIG,
            _bundled("sim", "mujoco", "rigs", "E1.yaml"),
            _bundled("sim", "mujoco", "rigs", "E3.yaml"),
        ],
    ),
    "consignment": (
        load_consignment,
        Consignment,
        [
            CONSIGNMENT,
            _bundled("sim", "mujoco", "consignments", "PB.yaml"),
            _bundled("sim", "mujoco", "consignments", "KPBW.yaml"),
        ],
    ),
}

# -- random YAML values ----------------------------------------------------------------------

JUNK_TEXT = [
    "",
    " ",
    "\u2028",
    "\u202e",
    "\u200b",
    "\ufeff",
    "\x85",
    "\t",
    "all",
    "null",
    "1e9",
    "-0",
    "../x.yaml",
    "E9",
    "R/P/\u00b2",
    "\u00e9\u00e8\u4e2d\U0001f4e6",
    "x" * 300,
]
EXTREME_NUMBERS = [
    0,
    -1,
    1,
    2,
    10**9,
    -(10**9),
    10**30,
    2**64,
    10**400,
    0.5,
    -0.5,
    1e308,
    -1e308,
    1e-320,
    -0.0,
    math.nan,
    math.inf,
    -math.inf,
]
scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from(EXTREME_NUMBERS),
    st.text(max_size=12),
    st.sampled_from(JUNK_TEXT),
)
keys = st.one_of(st.text(max_size=10), st.integers(-3, 20), st.sampled_from(["low", "high", "x"]))
values = st.recursive(
    scalars,
    lambda children: st.lists(children, max_size=4) | st.dictionaries(keys, children, max_size=4),
    max_leaves=8,
)


def _paths(
    node: Any, path: tuple[Any, ...] = (), seen: set[int] | None = None
) -> Iterator[tuple[Any, ...]]:
    """Every place in a document: the root, each mapping key's value and each list item; a
    list or mapping that appears more than once (an alias, a bomb) is entered once."""
    seen = set() if seen is None else seen
    yield path
    if isinstance(node, dict | list):
        if id(node) in seen:
            return
        seen.add(id(node))
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, (*path, k), seen)
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, (*path, i), seen)


def _get(doc: Any, path: tuple[Any, ...]) -> Any:
    for key in path:
        doc = doc[key]
    return doc


def _set(doc: Any, path: tuple[Any, ...], value: Any) -> Any:
    if not path:
        return value
    _get(doc, path[:-1])[path[-1]] = value
    return doc


def _bomb(levels: int) -> list[Any]:
    """Nested lists of nine, each level the same object nine times: an alias bomb once dumped."""
    node: list[Any] = ["lol"] * 9
    for _ in range(levels - 1):
        node = [node] * 9
    return node


def _nested(depth: int) -> list[Any]:
    node: list[Any] = []
    for _ in range(depth):
        node = [node]
    return node


MUTATIONS = ("delete", "replace", "number", "text", "add", "share", "bomb", "nest")


def _mutate(doc: Any, data: st.DataObject) -> Any:
    """One random change of the document's tree. Most keep the document's shape (a number
    becomes a huge, negative or non-finite one, a text becomes junk, a key goes or comes) so
    that the checks behind the type checks are reached too."""
    op = data.draw(st.sampled_from(MUTATIONS), label="mutation")
    places = [p for p in _paths(doc) if p] or [()]

    def leaves(test: Callable[[Any], bool]) -> list[tuple[Any, ...]]:
        return [p for p in places if test(_get(doc, p))] or places

    if op == "number":
        path = data.draw(
            st.sampled_from(
                leaves(lambda v: isinstance(v, int | float) and not isinstance(v, bool))
            )
        )
        return _set(doc, path, data.draw(st.sampled_from(EXTREME_NUMBERS), label="number"))
    if op == "text":
        path = data.draw(st.sampled_from(leaves(lambda v: isinstance(v, str))), label="place")
        junk = data.draw(st.sampled_from(JUNK_TEXT) | st.text(max_size=12), label="text")
        return _set(doc, path, junk)
    if op == "delete":
        path = data.draw(st.sampled_from(leaves(lambda v: isinstance(v, dict | list) and bool(v))))
        node = _get(doc, path)
        if isinstance(node, dict | list) and node:
            index = data.draw(
                st.sampled_from(list(node.keys() if isinstance(node, dict) else range(len(node))))
            )
            del node[index]
        return doc
    if op == "add":
        path = data.draw(st.sampled_from(leaves(lambda v: isinstance(v, dict))), label="place")
        node = _get(doc, path)
        if isinstance(node, dict):
            node[data.draw(keys, label="key")] = data.draw(values, label="value")
        return doc
    path = data.draw(st.sampled_from(places), label="place")
    if op == "share":  # the same object at two places: dumped as &anchor and *alias
        other = data.draw(st.sampled_from(places), label="other place")
        if other[: len(path)] != path and path[: len(other)] != other:
            return _set(doc, other, _get(doc, path))
        return doc
    if op == "bomb":
        return _set(doc, path, _bomb(data.draw(st.integers(2, 9), label="levels")))
    if op == "nest":
        return _set(doc, path, _nested(data.draw(st.integers(10, 80), label="depth")))
    return _set(doc, path, data.draw(values, label="value"))


def _text_mutation(text: str, data: st.DataObject) -> bytes:
    """One random change of the file's text: a line written twice, a character inserted, the
    text cut short, a byte that is not UTF-8, or none."""
    op = data.draw(st.sampled_from(["none", "twice", "insert", "cut", "byte"]), label="text op")
    lines = text.splitlines(keepends=True)
    if op == "twice" and lines:
        k = data.draw(st.integers(0, len(lines) - 1), label="line")
        lines.insert(data.draw(st.integers(k, len(lines)), label="at"), lines[k])
        return "".join(lines).encode()
    if op == "insert":
        at = data.draw(st.integers(0, len(text)), label="at")
        char = data.draw(
            st.sampled_from(
                ["\u2028", "\t", ":", "&", "*", "[", "{", "'", "\x00", "\ufeff", "!!", "- "]
            )
        )
        return (text[:at] + char + text[at:]).encode()
    if op == "cut":
        return text[: data.draw(st.integers(0, len(text)), label="cut at")].encode()
    if op == "byte":
        raw = text.encode()
        at = data.draw(st.integers(0, len(raw)), label="at")
        return (
            raw[:at]
            + data.draw(st.sampled_from([b"\xff", b"\xe9", b"\xc3", b"\x80\x80"]))
            + raw[at:]
        )
    return text.encode()


def _dump(doc: Any) -> str:
    try:
        return yaml.safe_dump(doc, sort_keys=False, allow_unicode=True)
    except (yaml.YAMLError, RecursionError, ValueError):  # e.g. an unorderable key
        return yaml.safe_dump({"x": 1})


@contextlib.contextmanager
def _time_limit(seconds: float) -> Iterator[None]:
    """Fail (instead of waiting for ever) if the block runs longer than ``seconds``."""

    def hung(signum: int, frame: Any) -> None:
        raise TimeoutError(f"still running after {seconds} s: the loader hangs")

    previous = signal.signal(signal.SIGALRM, hung)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def _loads_or_refuses(load: Callable[[Path], Any], kind: type, path: Path, root: Path) -> None:
    """``load(path)`` returns a ``kind`` or raises a `ParcelfitError` that names a file (below
    ``root``) on one line; any other exception fails the test."""
    try:
        with _time_limit(HANG_S):
            got = load(path)
    except ParcelfitError as exc:
        text = str(exc)
        event("refused")  # shown by pytest --hypothesis-show-statistics
        assert exc.file is not None and Path(exc.file).is_relative_to(root), text
        assert len(text.splitlines()) == 1 and len(text) < 2000, text
        return
    event("loaded")
    assert isinstance(got, kind)


@pytest.mark.parametrize("kind", list(LOADERS))
@LOADER_SETTINGS
@given(data=st.data())
def test_a_mutated_file_loads_or_is_refused_with_a_parcelfit_error(tmp_path, kind, data):
    load, returns, bases = LOADERS[kind]
    doc = copy.deepcopy(data.draw(st.sampled_from(bases), label="base"))
    for _ in range(data.draw(st.integers(0, 3), label="mutations")):
        doc = _mutate(doc, data)
    path = tmp_path / "file.yaml"
    path.write_bytes(_text_mutation(_dump(doc), data))
    _loads_or_refuses(load, returns, path, tmp_path)


@pytest.mark.parametrize("kind", list(LOADERS))
@LOADER_SETTINGS
@given(doc=values)
def test_a_random_document_loads_or_is_refused_with_a_parcelfit_error(tmp_path, kind, doc):
    load, returns, _ = LOADERS[kind]
    path = tmp_path / "file.yaml"
    path.write_text(_dump(doc), encoding="utf-8")
    _loads_or_refuses(load, returns, path, tmp_path)


# -- datasets: dataset.yaml and its run files -------------------------------------------------


@pytest.fixture(scope="module")
def valid_dataset(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("valid") / "data"
    write_reference_dataset(folder, n_runs=2)
    return folder


JUNK_CELLS = ["", "nan", "inf", "-inf", "1e400", "x", "\u2028", "1,5", '"', "0x10", "1e9"]


def _mutate_run_file(path: Path, data: st.DataObject) -> None:
    """One random change of a run file (CSV): emptied, cut short, a cell replaced with junk, a
    column dropped or added, two rows swapped, a byte that is not UTF-8, a byte-order mark."""
    op = data.draw(
        st.sampled_from(["empty", "cut", "cell", "drop", "add", "swap", "byte", "bom"]),
        label="run file op",
    )
    raw = path.read_bytes()
    lines = raw.decode("utf-8", "replace").splitlines()
    if not lines or not lines[0]:  # emptied by an earlier change
        op = "bom"
    if op == "empty":
        path.write_bytes(b"")
    elif op == "cut":
        path.write_bytes(raw[: data.draw(st.integers(0, len(raw)), label="cut at")])
    elif op == "cell":
        row = data.draw(st.integers(0, len(lines) - 1), label="row")
        cells = lines[row].split(",")
        col = data.draw(st.integers(0, len(cells) - 1), label="column")
        cells[col] = data.draw(st.sampled_from(JUNK_CELLS) | st.text(max_size=6), label="cell")
        lines[row] = ",".join(cells)
        path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    elif op in ("drop", "add"):
        rows = [line.split(",") for line in lines]
        col = data.draw(st.integers(0, len(rows[0]) - 1), label="column")
        for r in rows:
            if col >= len(r):  # a row cut short by an earlier change
                continue
            if op == "drop":
                del r[col]
            else:
                r.insert(col, r[col])
        path.write_text("\n".join(",".join(r) for r in rows) + "\n", encoding="utf-8")
    elif op == "swap" and len(lines) > 3:
        i = data.draw(st.integers(1, len(lines) - 2), label="row")
        lines[i], lines[i + 1] = lines[i + 1], lines[i]
        path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    elif op == "byte":
        at = data.draw(st.integers(0, len(raw)), label="at")
        path.write_bytes(raw[:at] + b"\xe9" + raw[at:])
    elif op == "bom":
        path.write_bytes(b"\xef\xbb\xbf" + raw)


@LOADER_SETTINGS
@given(data=st.data())
def test_a_mutated_dataset_loads_or_is_refused_with_a_parcelfit_error(
    tmp_path, valid_dataset, data
):
    folder = tmp_path / "data"
    shutil.rmtree(folder, ignore_errors=True)
    shutil.copytree(valid_dataset, folder)
    yaml_file = folder / "dataset.yaml"
    if data.draw(st.booleans(), label="change dataset.yaml"):
        doc = load_yaml(yaml_file)
        for _ in range(data.draw(st.integers(1, 3), label="mutations")):
            doc = _mutate(doc, data)
        yaml_file.write_bytes(_text_mutation(_dump(doc), data))
    else:
        runs = sorted((folder / "runs").iterdir())
        for _ in range(data.draw(st.integers(1, 2), label="run file changes")):
            _mutate_run_file(data.draw(st.sampled_from(runs), label="run file"), data)
    _loads_or_refuses(load_dataset, Dataset, folder, tmp_path)
