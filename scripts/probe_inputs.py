"""Probe parcelfit's command line with a fixed corpus of malformed inputs (issue 51: no input
hangs or breaks it) and count how each one ends.

    python scripts/probe_inputs.py [--only N] [--verbose] [--timeout 20] [--keep FOLDER]

Every input is a file (study, screen, twin spec, tag map, rig, consignment, dataset and run files)
or a command-line option made wrong in one way, run through ``python -m parcelfit`` in its own
folder (a subprocess with a time limit, killed with its process group when the limit passes).
Studies and screens use the analytic test simulator (``backend: python``, tests/fake_sim.py)
with short budgets, so that an input that is wrongly accepted finishes in seconds. A command
that would simulate with MuJoCo once its input is accepted (twin specs, rigs, consignments) is
given an option that stops it right after loading (e.g. ``--setting 999``), so the message tells
whether the file itself was refused.

Each input ends as one of:

- clean: exit status 2 and one line on stderr, ``error: ...``, naming the input's file or key;
- unclear: exit status 2, but more than one line, or a line that does not name the file or key
  (e.g. the input was accepted and something later refused);
- hung: no answer within the time limit;
- crashed: a Python traceback, or an exit status other than 0, 1 and 2;
- exit 0: the input was accepted without a word;
- other: exit status 1 without a traceback.

The corpus is the same on every run (no randomness); the counts per category and the total are
printed at the end (the figures of docs/reliability.md).
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

ROOT = Path(__file__).resolve().parents[1]
OUTCOMES = ("clean", "unclear", "hung", "crashed", "exit 0", "other")


@dataclass(frozen=True)
class Case:
    """One malformed input: its category, a name, how to make it in a fresh folder (returning
    the command's arguments after ``parcelfit``) and the words its message must hold (its
    file's name or the key or option at fault; any one of them)."""

    category: str
    name: str
    make: Callable[[Path], list[str]]
    names: tuple[str, ...]


# -- valid documents, made wrong one way per case ---------------------------------------------

SIM = {"backend": "python", "factory": "tests.fake_sim:make"}
REF = {"dataset": "data", "rig": "R", "consignment": "P", "speed_setting": 1}
STUDY: dict[str, Any] = {
    "name": "probe",
    "simulator": SIM,
    "parameters": {"mu_d_BePa": [0.3, 0.6], "mu_d_MePa": [0.15, 0.35]},
    "reference": REF,
    "validation": {"speed_setting": 2, "every": 1},
    "batch_size": 2,
    "initial": 4,
    "budget": 6,
    "seed": 1,
    "optimizer": {"n_samples": 200, "n_restarts": 1},
    "executor": "serial",
}
SCREEN: dict[str, Any] = {
    "name": "probe-screen",
    "simulator": SIM,
    "reference": REF,
    "parameters": {"mu_d_BePa": [0.3, 0.58], "mu_d_MePa": [0.15, 0.35]},
    "stages": ["full"],
    "executor": "serial",
}
TWIN: dict[str, Any] = {
    "cases": ["E1/BW/1"],
    "truth": {"BW": {"mu_d_BePa": 0.5}},
    "settings": {"runs": 2},
}
TAGS: dict[str, Any] = {
    "reference_tags": {0: {"x": 0.0, "y": 0.0, "size": 0.08}},
    "parcel_tags": {5: {"size": 0.06}},
    "camera": {"fx": 1000, "fy": 1000, "cx": 640, "cy": 360},
    "light_barriers": [{"id": "start", "from": [0.2, -0.5], "to": [0.2, 0.5]}],
}
RIG: dict[str, Any] = {
    "name": "R",
    "speeds": {1: {"main": 1.5}},
    "surfaces": [
        {
            "name": "main",
            "type": "belt",
            "material": "belt",
            "centre": [1, 0],
            "length": 3,
            "width": 0.8,
            "heading": 0,
            "top": 0,
            "drive": "main",
        }
    ],
    "walls": [{"name": "guide", "from": [0.1, -0.5], "to": [1.3, -0.2], "height": 0.1}],
    "start": {"position": [0.0, 0.0], "heading": 0, "surface": "main", "scatter": {}},
    "light_barriers": [
        {"name": "LS1", "from": [0.2, -0.4], "to": [0.2, 0.4]},
        {"name": "LS2", "from": [1.8, -0.4], "to": [1.8, 0.4]},
    ],
    "regions": [{"x": [-0.2, 1.6]}],
    "end": {"x": [-1, 2.5], "y": [-1, 1], "duration": 2},
}
CONSIGNMENT: dict[str, Any] = {
    "name": "C",
    "mass": 0.14,
    "outer": [0.275, 0.2, 0.02],
    "content": {"kind": "rigid", "size": [0.165, 0.125, 0.02]},
}

ALIAS_BOMB = "\n".join(
    ["  a: &a [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    + [
        f"  {n}: &{n} [{', '.join([f'*{p}'] * 9)}]"
        for p, n in zip("abcdefgh", "bcdefghi", strict=True)
    ]
)


def _copy(doc: dict[str, Any]) -> dict[str, Any]:
    return copy.deepcopy(doc)


def _dump(doc: Any) -> str:
    return yaml.safe_dump(doc, sort_keys=False, allow_unicode=True)


def _dataset(folder: Path) -> Path:
    """The analytic simulator's reference dataset (R/P/1 and R/P/2, three runs each)."""
    sys.path.insert(0, str(ROOT))
    from tests.fake_sim import write_reference_dataset

    write_reference_dataset(folder / "data", n_runs=3)
    return folder / "data"


def _write(folder: Path, name: str, content: str | bytes) -> Path:
    path = folder / name
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content, encoding="utf-8")
    return path


def study(
    edit: Callable[[dict[str, Any]], Any] | None = None,
    *,
    text: str | bytes | None = None,
    append: str = "",
    extra: list[str] | None = None,
) -> Callable[[Path], list[str]]:
    """``calibrate study.yaml`` for the base study changed by ``edit`` (or the raw ``text``)."""

    def make(folder: Path) -> list[str]:
        _dataset(folder)
        doc = _copy(STUDY)
        if edit is not None:
            edit(doc)
        path = _write(folder, "study.yaml", text if text is not None else _dump(doc) + append)
        return ["calibrate", str(path), "--out", str(folder / "out"), *(extra or [])]

    return make


def screen(edit: Callable[[dict[str, Any]], Any] | None = None, *, append: str = "") -> Any:
    def make(folder: Path) -> list[str]:
        _dataset(folder)
        doc = _copy(SCREEN)
        if edit is not None:
            edit(doc)
        path = _write(folder, "screen.yaml", _dump(doc) + append)
        return ["screen", str(path), "--out", str(folder / "out")]

    return make


def twin(
    edit: Callable[[dict[str, Any]], Any] | None = None, *, text: str | bytes | None = None
) -> Any:
    """``synth twin.yaml`` (an accepted spec would start simulating with MuJoCo: the time
    limit stops it, and it counts as hung)."""

    def make(folder: Path) -> list[str]:
        doc = _copy(TWIN)
        if edit is not None:
            edit(doc)
        path = _write(folder, "twin.yaml", text if text is not None else _dump(doc))
        return ["synth", str(path), "--out", str(folder / "out"), "--workers", "1"]

    return make


def tags(edit: Callable[[dict[str, Any]], Any] | None = None, *, append: str = "") -> Any:
    """``track`` a video that does not exist with the tag map: the tag map is read first."""

    def make(folder: Path) -> list[str]:
        doc = _copy(TAGS)
        if edit is not None:
            edit(doc)
        path = _write(folder, "tags.yaml", _dump(doc) + append)
        return ["track", str(folder / "no-video.mp4"), "--tags", str(path), "--out", str(folder)]

    return make


def rig(edit: Callable[[dict[str, Any]], Any] | None = None, *, append: str = "") -> Any:
    """``simulate --rig rig.yaml --setting 999``: an accepted rig stops at the speed setting."""

    def make(folder: Path) -> list[str]:
        doc = _copy(RIG)
        if edit is not None:
            edit(doc)
        path = _write(folder, "rig.yaml", _dump(doc) + append)
        return ["simulate", "--rig", str(path), "--setting", "999", "--out", str(folder / "r.csv")]

    return make


def consignment(edit: Callable[[dict[str, Any]], Any] | None = None, *, append: str = "") -> Any:
    """``simulate --consignment cons.yaml --setting 999`` (stops before simulating)."""

    def make(folder: Path) -> list[str]:
        doc = _copy(CONSIGNMENT)
        if edit is not None:
            edit(doc)
        path = _write(folder, "cons.yaml", _dump(doc) + append)
        return [
            "simulate",
            "--consignment",
            str(path),
            "--setting",
            "999",
            "--out",
            str(folder / "r.csv"),
        ]

    return make


def dataset(
    edit: Callable[[dict[str, Any]], Any] | None = None,
    *,
    run: Callable[[Path], Any] | None = None,
    text: bytes | None = None,
) -> Any:
    """``reference data`` for the analytic dataset with ``dataset.yaml`` (``edit``, ``text``)
    or its first run file (``run``) made wrong."""

    def make(folder: Path) -> list[str]:
        data = _dataset(folder)
        if edit is not None:
            doc = yaml.safe_load((data / "dataset.yaml").read_text())
            edit(doc)
            (data / "dataset.yaml").write_text(_dump(doc))
        if text is not None:
            (data / "dataset.yaml").write_bytes(text)
        if run is not None:
            run(data / "runs" / "R-P-1-0.csv")
        return ["reference", str(data)]

    return make


def command(*args: str, study_file: bool = False) -> Callable[[Path], list[str]]:
    """A command line as given; ``{study}`` stands for a valid study file, ``{dir}`` for the
    case's folder."""

    def make(folder: Path) -> list[str]:
        path = ""
        if study_file:
            _dataset(folder)
            path = str(_write(folder, "study.yaml", _dump(STUDY)))
        return [a.replace("{study}", path).replace("{dir}", str(folder)) for a in args]

    return make


def _set(path: str, value: Any) -> Callable[[dict[str, Any]], None]:
    """An edit setting the key ``path`` (``a.b.0``) to ``value``."""

    def edit(doc: dict[str, Any]) -> None:
        keys = [int(k) if k.isdigit() else k for k in path.split(".")]
        node = doc
        for k in keys[:-1]:
            node = node[k]
        node[keys[-1]] = value

    return edit


def _drop(path: str) -> Callable[[dict[str, Any]], None]:
    def edit(doc: dict[str, Any]) -> None:
        keys = [int(k) if k.isdigit() else k for k in path.split(".")]
        node = doc
        for k in keys[:-1]:
            node = node[k]
        del node[keys[-1]]

    return edit


def _rewrite(transform: Callable[[str], str]) -> Callable[[Path], None]:
    """A run-file change: its text through ``transform``."""

    def change(path: Path) -> None:
        path.write_text(transform(path.read_text()), encoding="utf-8")

    return change


def _cell(row: int, col: int, value: str) -> Callable[[Path], None]:
    def transform(text: str) -> str:
        lines = text.splitlines()
        cells = lines[row].split(",")
        cells[col] = value
        lines[row] = ",".join(cells)
        return "\n".join(lines) + "\n"

    return _rewrite(transform)


def _swap_rows(text: str) -> str:
    lines = text.splitlines()
    lines[5], lines[6] = lines[6], lines[5]
    return "\n".join(lines) + "\n"


def _times_in_ms(text: str) -> str:
    lines = text.splitlines()
    out = [lines[0]]
    for line in lines[1:]:
        t, *rest = line.split(",")
        out.append(",".join([repr(float(t) * 1000), *rest]))
    return "\n".join(out) + "\n"


def _outside(doc: dict[str, Any]) -> None:
    doc["test_cases"][0]["runs"][0]["file"] = "../outside.csv"


def _same_id(doc: dict[str, Any]) -> None:
    runs = doc["test_cases"][0]["runs"]
    runs[1]["id"] = runs[0]["id"]


S = "study.yaml"
BIG = 10**30
CASES: list[Case] = [
    # -- study files (calibrate, analytic simulator) --
    Case(
        "study",
        "alias bomb",
        study(_drop("parameters"), append="parameters:\n" + ALIAS_BOMB + "\n"),
        (S,),
    ),
    Case("study", "key written twice", study(append="budget: 12\n"), (S,)),
    Case("study", "recursive alias", study(append="extra: &x [1, *x]\n"), (S,)),
    Case("study", "nested 100 deep", study(append="extra: " + "[" * 100 + "]" * 100 + "\n"), (S,)),
    Case("study", "whole number of 5000 digits", study(append="extra: " + "9" * 5000 + "\n"), (S,)),
    Case("study", "date 2024-13-45", study(append="extra: 2024-13-45\n"), (S,)),
    Case("study", "empty file", study(text=""), (S,)),
    Case("study", "not UTF-8", study(text=b"name: caf\xe9\n"), (S,)),
    Case("study", "unclosed bracket", study(text="name: [probe\n"), (S,)),
    Case("study", "tab indentation", study(text="name: p\nsimulator:\n\tbackend: python\n"), (S,)),
    Case("study", "a list at the top", study(text="- name\n- p\n"), (S,)),
    Case("study", "17 MiB", study(text="# " + "x" * (17 * 2**20) + "\nname: p\n"), (S,)),
    Case("study", "initial 1e9", study(_set("initial", 1e9)), ("initial",)),
    Case("study", "budget 1e9", study(_set("budget", 1e9)), ("budget",)),
    Case("study", "batch_size 1e6", study(_set("batch_size", 10**6)), ("batch_size",)),
    Case("study", "budget below initial", study(_set("budget", 2)), ("budget",)),
    Case("study", "budget 2.9", study(_set("budget", 2.9)), ("budget",)),
    Case("study", "budget 'many'", study(_set("budget", "many")), ("budget",)),
    Case(
        "study",
        "workers 1e5",
        study(_set("executor", {"kind": "local", "workers": 10**5})),
        ("executor.workers",),
    ),
    Case("study", "executor slurm", study(_set("executor", "slurm")), ("executor",)),
    Case("study", "seed -1", study(_set("seed", -1)), ("seed",)),
    Case("study", "seed 1e30", study(_set("seed", 1e30)), ("seed",)),
    Case(
        "study",
        "validation every 1e9",
        study(_set("validation.every", 10**9)),
        ("validation.every",),
    ),
    Case(
        "study",
        "validation setting 7",
        study(_set("validation.speed_setting", 7)),
        ("validation.speed_setting",),
    ),
    Case(
        "study",
        "validation setting = fitted",
        study(_set("validation.speed_setting", 1)),
        ("validation.speed_setting",),
    ),
    Case(
        "study",
        "reference setting 1e30",
        study(_set("reference.speed_setting", BIG)),
        ("reference.speed_setting",),
    ),
    Case(
        "study",
        "reference dataset missing",
        study(_set("reference.dataset", "nowhere")),
        ("nowhere", S),
    ),
    Case("study", "no reference", study(_drop("reference")), ("reference",)),
    Case("study", "unknown key", study(_set("budgett", 10)), ("budgett",)),
    Case("study", "name empty", study(_set("name", "")), ("name",)),
    Case("study", "name a list", study(_set("name", ["a"])), ("name",)),
    Case(
        "study",
        "friction [-0.5, -0.1]",
        study(_set("parameters.mu_d_BePa", [-0.5, -0.1])),
        ("parameters.mu_d_BePa",),
    ),
    Case(
        "study",
        "friction [5, 9]",
        study(_set("parameters.mu_d_BePa", [5, 9])),
        ("parameters.mu_d_BePa",),
    ),
    Case(
        "study",
        "modulus [-100, 100]",
        study(_set("parameters.E_Pa", [-100, 100])),
        ("parameters.E_Pa",),
    ),
    Case(
        "study",
        "bounds [nan, 1]",
        study(_set("parameters.mu_d_BePa", [math.nan, 1])),
        ("parameters.mu_d_BePa",),
    ),
    Case(
        "study",
        "bounds [0.3, inf]",
        study(_set("parameters.mu_d_BePa", [0.3, math.inf])),
        ("parameters.mu_d_BePa",),
    ),
    Case(
        "study",
        "bounds reversed",
        study(_set("parameters.mu_d_BePa", [0.6, 0.3])),
        ("parameters.mu_d_BePa",),
    ),
    Case(
        "study",
        "bounds a word",
        study(_set("parameters.mu_d_BePa", "wide")),
        ("parameters.mu_d_BePa",),
    ),
    Case(
        "study",
        "bounds of 5000 numbers",
        study(_set("parameters.mu_d_BePa", list(range(5000)))),
        ("parameters.mu_d_BePa",),
    ),
    Case(
        "study",
        "log 'false'",
        study(_set("parameters.mu_d_BePa", {"low": 0.3, "high": 0.6, "log": "false"})),
        ("parameters.mu_d_BePa.log",),
    ),
    Case("study", "fixed stiffness -5", study(_set("fixed", {"k_BePa": -5})), ("fixed.k_BePa",)),
    Case("study", "fitted and fixed", study(_set("fixed", {"mu_d_BePa": 0.4})), ("fixed",)),
    Case("study", "weights 0/0", study(_set("weights", {"xy": 0, "theta": 0})), ("weights",)),
    Case(
        "study",
        "optimizer n_samples 1e9",
        study(_set("optimizer", {"n_samples": 1e9})),
        ("optimizer.n_samples",),
    ),
    Case(
        "study",
        "optimizer ucb_lambda 'wide'",
        study(_set("optimizer", {"ucb_lambda": "wide"})),
        ("optimizer.ucb_lambda",),
    ),
    Case(
        "study",
        "optimizer unknown setting",
        study(_set("optimizer", {"lambda": 2})),
        ("optimizer",),
    ),
    Case(
        "study",
        "backend quantum",
        study(_set("simulator.backend", "quantum")),
        ("simulator.backend",),
    ),
    Case(
        "study",
        "factory module missing",
        study(_set("simulator.factory", "nowhere.sim:make")),
        (S,),
    ),
    Case(
        "study",
        "mujoco rig E9",
        study(_set("simulator", {"backend": "mujoco", "rig": "E9", "consignment": "KPBW"})),
        ("simulator.rig",),
    ),
    Case(
        "study",
        "cost placements 1e5",
        study(_set("cost", {"kind": "ensemble", "placements": 10**5})),
        ("cost.placements",),
    ),
    Case("study", "rig name with U+2028", study(_set("reference.rig", "R\u2028x")), ("reference",)),
    # -- screen files --
    Case(
        "screen",
        "alias bomb",
        screen(_drop("parameters"), append="parameters:\n" + ALIAS_BOMB + "\n"),
        ("screen.yaml",),
    ),
    Case("screen", "key written twice", screen(append="name: again\n"), ("screen.yaml",)),
    Case("screen", "select 1e6", screen(_set("select", 10**6)), ("select",)),
    Case("screen", "centre_points 1e6", screen(_set("centre_points", 10**6)), ("centre_points",)),
    Case("screen", "resolution 9", screen(_set("resolution", 9)), ("resolution",)),
    Case(
        "screen",
        "friction range [-1, 0.5]",
        screen(_set("parameters.mu_d_BePa", [-1, 0.5])),
        ("parameters.mu_d_BePa",),
    ),
    Case("screen", "fixed modulus 'big'", screen(_set("fixed", {"E_Pa": "big"})), ("fixed.E_Pa",)),
    Case("screen", "stages 5", screen(_set("stages", 5)), ("stages",)),
    Case(
        "screen", "workers 1e5", screen(_set("executor", {"workers": 10**5})), ("executor.workers",)
    ),
    Case("screen", "alpha 2", screen(_set("alpha", 2)), ("alpha",)),
    Case(
        "screen", "soft_content unknown", screen(_set("soft_content", ["E_Cox"])), ("soft_content",)
    ),
    Case("screen", "one parameter", screen(_set("parameters", ["mu_d_BePa"])), ("parameters",)),
    Case(
        "screen",
        "mujoco consignment XX",
        screen(_set("simulator", {"backend": "mujoco", "rig": "E3", "consignment": "XX"})),
        ("simulator.consignment",),
    ),
    # -- twin specs (synth) --
    Case("twin spec", "unknown rig E9", twin(_set("cases", ["E9/BW/1"])), ("twin.yaml",)),
    Case(
        "twin spec", "speed setting the rig lacks", twin(_set("cases", ["E1/BW/9"])), ("twin.yaml",)
    ),
    Case("twin spec", "unknown consignment", twin(_set("cases", ["E1/XX/1"])), ("twin.yaml",)),
    Case("twin spec", "case E1-BW-1", twin(_set("cases", ["E1-BW-1"])), ("cases",)),
    Case("twin spec", "case with setting ²", twin(_set("cases", ["E1/BW/\u00b2"])), ("cases",)),
    Case("twin spec", "no cases", twin(_set("cases", [])), ("cases",)),
    Case("twin spec", "runs 1e9", twin(_set("settings.runs", 1e9)), ("settings.runs",)),
    Case("twin spec", "seed -1", twin(_set("seed", -1)), ("seed",)),
    Case(
        "twin spec", "true friction 5", twin(_set("truth.BW.mu_d_BePa", 5)), ("truth.BW.mu_d_BePa",)
    ),
    Case(
        "twin spec",
        "soft parameter on a rigid content",
        twin(_set("truth.BW.E_Co", 0.1)),
        ("truth.BW.E_Co",),
    ),
    Case("twin spec", "unknown settings key", twin(_set("settings.runz", 3)), ("settings",)),
    Case(
        "twin spec",
        "key written twice",
        twin(text="cases: [E1/BW/1]\ncases: [E1/BW/2]\n"),
        ("twin.yaml",),
    ),
    Case("twin spec", "not UTF-8", twin(text=b"cases: [E1/BW/1]\nname: caf\xe9\n"), ("twin.yaml",)),
    # -- tag maps (track) --
    Case("tag map", "missing fx", tags(_drop("camera.fx")), ("camera",)),
    Case(
        "tag map",
        "tag size 3 m",
        tags(_set("reference_tags.0.size", 3)),
        ("reference_tags.0.size",),
    ),
    Case(
        "tag map",
        "tag id 'five'",
        tags(_set("parcel_tags", {"five": {"size": 0.06}})),
        ("parcel_tags",),
    ),
    Case(
        "tag map",
        "a tag with two roles",
        tags(_set("parcel_tags", {0: {"size": 0.06}})),
        ("parcel_tags.0",),
    ),
    Case("tag map", "image width 1e9", tags(_set("camera.width", 10**9)), ("camera.width",)),
    Case(
        "tag map",
        "distortion of 400 digits",
        tags(_set("camera.distortion", [0, 0, 0, 10**400])),
        ("camera.distortion",),
    ),
    Case("tag map", "key written twice", tags(append="parcel_tags: {}\n"), ("tags.yaml",)),
    Case(
        "tag map",
        "light barriers a mapping",
        tags(_set("light_barriers", {"a": 1})),
        ("light_barriers",),
    ),
    # -- rigs (simulate --rig FILE) --
    Case("rig", "speed setting 0", rig(_set("speeds", {0: {"main": 1}})), ("speeds",)),
    Case("rig", "speed setting 1e20", rig(_set("speeds", {10**20: {"main": 1}})), ("speeds",)),
    Case(
        "rig",
        "drive without a speed",
        rig(_set("surfaces.0.drive", "fast")),
        ("surfaces[0].drive",),
    ),
    Case(
        "rig",
        "region with a number key",
        rig(_set("regions", [{"x": [0, 1], 0: 1}])),
        ("regions[0]",),
    ),
    Case(
        "rig",
        "polygon of 400 digits",
        rig(_set("regions", [{"polygon": [[0, 0], [1, 0], [10**400, 1]]}])),
        ("regions[0]",),
    ),
    Case("rig", "one light barrier", rig(lambda d: d["light_barriers"].pop()), ("light_barriers",)),
    Case("rig", "length 'long'", rig(_set("surfaces.0.length", "long")), ("surfaces[0].length",)),
    Case("rig", "heading nan", rig(_set("surfaces.0.heading", math.nan)), ("surfaces[0].heading",)),
    Case("rig", "start on no surface", rig(_set("start.surface", "floor")), ("start.surface",)),
    Case("rig", "key written twice", rig(append="name: again\n"), ("rig.yaml",)),
    # -- consignments (simulate --consignment FILE) --
    Case("consignment", "mass 1000 kg", consignment(_set("mass", 1000)), ("mass",)),
    Case("consignment", "outer of two numbers", consignment(_set("outer", [0.3, 0.2])), ("outer",)),
    Case(
        "consignment",
        "content too big",
        consignment(_set("content.size", [0.3, 0.1, 0.02])),
        ("content.size",),
    ),
    Case(
        "consignment",
        "content liquid",
        consignment(_set("content.kind", "liquid")),
        ("content.kind",),
    ),
    Case(
        "consignment",
        "own friction 9",
        consignment(_set("parameters", {"mu_d_BePa": 9})),
        ("parameters.mu_d_BePa",),
    ),
    Case(
        "consignment",
        "shell cells without a shell",
        consignment(_set("shell_cells", [4, 4, 1])),
        ("shell_cells",),
    ),
    Case("consignment", "key written twice", consignment(append="mass: 0.2\n"), ("cons.yaml",)),
    # -- datasets and run files (reference) --
    Case("dataset", "empty run file", dataset(run=lambda p: p.write_bytes(b"")), ("R-P-1-0.csv",)),
    Case(
        "dataset",
        "run file of blanks",
        dataset(run=lambda p: p.write_bytes(b"\n \n")),
        ("R-P-1-0.csv",),
    ),
    Case(
        "dataset",
        "run file not UTF-8",
        dataset(run=lambda p: p.write_bytes(p.read_bytes() + b"1,caf\xe9,0,0\n")),
        ("R-P-1-0.csv",),
    ),
    Case(
        "dataset",
        "run file malformed CSV",
        dataset(run=lambda p: p.write_text('t,x,y,theta\n0,0,0,"0\n')),
        ("R-P-1-0.csv",),
    ),
    Case(
        "dataset",
        "run file without theta",
        dataset(
            run=_rewrite(
                lambda t: "\n".join(",".join(r.split(",")[:3]) for r in t.splitlines()) + "\n"
            )
        ),
        ("R-P-1-0.csv",),
    ),
    Case("dataset", "a word for x", dataset(run=_cell(3, 1, "left")), ("R-P-1-0.csv",)),
    Case("dataset", "inf for y", dataset(run=_cell(3, 2, "inf")), ("R-P-1-0.csv",)),
    Case("dataset", "time going back", dataset(run=_rewrite(_swap_rows)), ("R-P-1-0.csv",)),
    Case("dataset", "times in milliseconds", dataset(run=_rewrite(_times_in_ms)), ("R-P-1-0.csv",)),
    Case(
        "dataset",
        "run file garbage parquet",
        dataset(
            edit=_set("test_cases.0.runs.0.file", "runs/x.parquet"),
            run=lambda p: (p.parent / "x.parquet").write_bytes(b"PAR1 not really"),
        ),
        ("x.parquet",),
    ),
    Case(
        "dataset",
        "transit time 1e300",
        dataset(_set("test_cases.0.runs.0.transit_time", 1e300)),
        ("transit_time",),
    ),
    Case(
        "dataset",
        "speed setting 1e30",
        dataset(_set("test_cases.0.speed_setting", BIG)),
        ("speed_setting",),
    ),
    Case("dataset", "run file outside", dataset(_outside), ("runs[0].file",)),
    Case("dataset", "run id twice", dataset(_same_id), ("runs[1].id",)),
    Case("dataset", "no test cases", dataset(_set("test_cases", [])), ("test_cases",)),
    Case("dataset", "dataset.yaml not UTF-8", dataset(text=b"name: caf\xe9\n"), ("dataset.yaml",)),
    Case(
        "dataset",
        "dataset.yaml key twice",
        dataset(text=b"name: a\nname: b\ntest_cases: []\n"),
        ("dataset.yaml",),
    ),
    Case(
        "dataset",
        "polygon region of 400 digits",
        dataset(_set("test_cases.0.regions", [{"polygon": [[0, 0], [1, 0], [10**400, 1]]}])),
        ("regions[0]",),
    ),
    # -- command-line options --
    Case(
        "option",
        "calibrate --workers 100000",
        command("calibrate", "{study}", "--out", "{dir}/o", "--workers", "100000", study_file=True),
        ("--workers",),
    ),
    Case(
        "option",
        "calibrate --executor cloud",
        command("calibrate", "{study}", "--out", "{dir}/o", "--executor", "cloud", study_file=True),
        ("executor",),
    ),
    Case(
        "option",
        "simulate --repeat 1000000",
        command("simulate", "--repeat", "1000000", "--out", "{dir}/r.csv"),
        ("--repeat",),
    ),
    Case(
        "option",
        "simulate --seed 2^40",
        command("simulate", "--seed", str(2**40), "--out", "{dir}/r.csv"),
        ("--seed",),
    ),
    Case(
        "option",
        "simulate --set mu_d_BePa=-1",
        command("simulate", "--set", "mu_d_BePa=-1", "--out", "{dir}/r.csv"),
        ("--set",),
    ),
    Case(
        "option",
        "simulate --set mu_d_BePa=nan",
        command("simulate", "--set", "mu_d_BePa=nan", "--out", "{dir}/r.csv"),
        ("--set",),
    ),
    Case(
        "option",
        "simulate --set nothing",
        command("simulate", "--set", "nothing", "--out", "{dir}/r.csv"),
        ("nothing",),
    ),
    Case(
        "option",
        "simulate --shell-cells 99,1,1",
        command("simulate", "--shell-cells", "99,1,1", "--out", "{dir}/r.csv"),
        ("shell",),
    ),
    Case(
        "option",
        "simulate --setting 99",
        command("simulate", "--setting", "99", "--out", "{dir}/r.csv"),
        ("setting",),
    ),
    Case(
        "option",
        "simulate --rig E9",
        command("simulate", "--rig", "E9", "--out", "{dir}/r.csv"),
        ("E9",),
    ),
    Case(
        "option",
        "precision --placements 5000",
        command(
            "precision", "{study}", "--placements", "5000", "--out", "{dir}/o", study_file=True
        ),
        ("--placements",),
    ),
    Case(
        "option",
        "precision --candidate R/P/²",
        command(
            "precision", "{study}", "--candidate", "R/P/\u00b2", "--out", "{dir}/o", study_file=True
        ),
        ("R/P/",),
    ),
    Case(
        "option",
        "precision --at mu_d_BePa=3",
        command("precision", "{study}", "--at", "mu_d_BePa=3", "--out", "{dir}/o", study_file=True),
        ("--at",),
    ),
    Case(
        "option",
        "camera-calibrate --board ²x6",
        command("camera-calibrate", "{dir}/v.mp4", "--tags", "{dir}/t.yaml", "--board", "\u00b2x6"),
        ("--board",),
    ),
    Case(
        "option",
        "synth --workers 100000",
        command("synth", "nowhere.yaml", "--workers", "100000"),
        ("--workers",),
    ),
    Case(
        "option",
        "reference of a missing folder",
        command("reference", "{dir}/nowhere"),
        ("nowhere",),
    ),
    Case(
        "option",
        "status of a folder without a store",
        command("status", "{dir}"),
        ("study.sqlite", "store", "{dir}"),
    ),
    Case(
        "option",
        "demo --quick --full",
        command("demo", "--quick", "--full", "--out", "{dir}/d"),
        ("--quick",),
    ),
]


def _run(case: Case, folder: Path, timeout: float) -> tuple[str, str]:
    """Make ``case`` in ``folder``, run it, and return its outcome and first stderr line."""
    args = case.make(folder)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(ROOT / "src")])}
    env.pop("CI", None)
    proc = subprocess.Popen(
        [sys.executable, "-m", "parcelfit", *args],
        cwd=folder,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own process group: killed whole at the time limit
    )
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        return "hung", f"no answer in {timeout:g} s"
    lines = [line for line in err.splitlines() if line.strip()]
    first = lines[0] if lines else (out.strip().splitlines() or [""])[0]
    if "Traceback (most recent call last)" in err or proc.returncode not in (0, 1, 2):
        return "crashed", next((x for x in reversed(lines) if x.strip()), first)
    if proc.returncode == 0:
        return "exit 0", first
    if proc.returncode == 1:
        return "other", first
    names = [n.replace("{dir}", str(folder)) for n in case.names]
    if len(lines) == 1 and lines[0].startswith("error: ") and any(n in lines[0] for n in names):
        return "clean", lines[0]
    return "unclear", " | ".join(lines)[:300]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", type=int, default=None, help="Run the first N inputs only.")
    ap.add_argument("--timeout", type=float, default=20.0, help="Time limit per input [s].")
    ap.add_argument("--verbose", action="store_true", help="Print every input's outcome.")
    ap.add_argument("--keep", type=Path, default=None, help="Keep the inputs in this folder.")
    args = ap.parse_args(argv)
    cases = CASES[: args.only] if args.only else CASES
    root = Path(tempfile.mkdtemp(prefix="probe-inputs-")) if args.keep is None else args.keep
    counts: dict[str, Counter[str]] = {}
    t0 = time.perf_counter()
    try:
        for k, case in enumerate(cases):
            folder = root / f"{k:03d}"
            folder.mkdir(parents=True, exist_ok=True)
            outcome, line = _run(case, folder, args.timeout)
            counts.setdefault(case.category, Counter())[outcome] += 1
            if args.verbose or outcome != "clean":
                print(f"{case.category} / {case.name}: {outcome}: {line}", flush=True)
    finally:
        if args.keep is None:
            shutil.rmtree(root, ignore_errors=True)
    width = max(len(c) for c in [*counts, "category"]) + 2
    print()
    print(f"{'category':<{width}}{'inputs':>7}" + "".join(f"{o:>9}" for o in OUTCOMES))
    total: Counter[str] = Counter()
    for category, c in counts.items():
        total.update(c)
        print(f"{category:<{width}}{sum(c.values()):>7}" + "".join(f"{c[o]:>9}" for o in OUTCOMES))
    print(
        f"{'total':<{width}}{sum(total.values()):>7}" + "".join(f"{total[o]:>9}" for o in OUTCOMES)
    )
    print(f"({time.perf_counter() - t0:.0f} s; clean: exit 2 with one line naming the file or key)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
