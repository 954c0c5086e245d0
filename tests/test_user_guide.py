"""Every command of the user guide runs, so the guide cannot rot.

The fenced ``bash`` and ``console`` blocks of the getting-started and user-guide pages
(docs/getting-started/, docs/guide/) are extracted and run in the site's order, in one working
folder laid out like a clone of the repository (a copy of ``examples/``, the bundled data, the
tracking example's script), with ``parcelfit`` and ``python`` the code under test. A block
preceded by an HTML comment steers it:

- ``<!-- ci: skip: REASON -->``: illustrative only (or too long for CI, an install, a cluster):
  not run; the reason is required;
- ``<!-- ci: replace OLD => NEW -->``: run with OLD replaced by NEW (shorter settings).

Every other block must run and exit with status 0. The blocks of the "Your own rig" page make
the dataset and the study that the later pages read, as a reader following the guide would.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import parcelfit

from .helpers import ROOT

DOCS = ROOT / "docs"
BLOCK = re.compile(r"^```(\w+)[^\n]*\n(.*?)^```\s*$", re.M | re.S)
DIRECTIVE = re.compile(r"<!--\s*ci:\s*(.*?)\s*-->\s*\Z", re.S)


def guide_pages() -> list[str]:
    """The getting-started and user-guide pages in the order of the site's navigation."""
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    return re.findall(r"^\s*- [^:]+: ((?:getting-started|guide)/[\w-]+\.md)\s*$", nav, re.M)


def blocks(page: str) -> list[tuple[str, str, str | None]]:
    """(language, text, directive) of every fenced block of ``page``."""
    text = (DOCS / page).read_text(encoding="utf-8")
    out = []
    for m in BLOCK.finditer(text):
        before = text[: m.start()].rstrip()
        directive = DIRECTIVE.search(before)
        out.append((m.group(1), m.group(2), directive.group(1) if directive else None))
    return out


def runnable(page: str) -> list[tuple[int, str]]:
    """The commands to run of ``page``: (block number, shell text), directives applied."""
    out = []
    for k, (lang, text, directive) in enumerate(blocks(page)):
        if lang not in ("bash", "console"):
            continue
        if directive is not None and directive.startswith("skip"):
            assert re.match(r"skip:\s*\S", directive), f"{page} block {k}: skip needs a reason"
            continue
        if lang == "console":
            text = "\n".join(line[2:] for line in text.splitlines() if line.startswith("$ "))
        if directive is not None:
            m = re.fullmatch(r"replace (.+?) => ?(.*)", directive, re.S)
            assert m, f"{page} block {k}: unknown directive {directive!r}"
            assert m.group(1) in text, f"{page} block {k}: {m.group(1)!r} not in the block"
            text = text.replace(m.group(1), m.group(2))
        out.append((k, text))
    return out


def test_the_guide_pages_are_found_and_every_skip_says_why():
    pages = guide_pages()
    assert "guide/rig.md" in pages and pages.index("guide/rig.md") < pages.index("guide/data.md")
    assert set(pages) == {
        str(p.relative_to(DOCS))
        for d in ("getting-started", "guide")
        for p in (DOCS / d).glob("*.md")
    }
    commands = {page: runnable(page) for page in pages}  # checks every directive
    assert commands["guide/rig.md"] and commands["guide/track.md"]


def _workspace(tmp_path: Path) -> tuple[Path, dict[str, str]]:
    """A folder laid out like a clone, and an environment whose parcelfit is the code under
    test."""
    work = tmp_path / "work"
    shutil.copytree(ROOT / "examples", work / "examples")
    data = work / "src" / "parcelfit" / "data"
    data.mkdir(parents=True)
    (data / "examples").symlink_to(Path(parcelfit.__file__).parent / "data" / "examples")
    (work / "scripts").mkdir()
    shutil.copy(ROOT / "scripts" / "make_tracking_example.py", work / "scripts")
    shims = tmp_path / "bin"
    shims.mkdir()
    for name, args in (("parcelfit", '-m parcelfit "$@"'), ("python", '"$@"'), ("python3", '"$@"')):
        shim = shims / name
        shim.write_text(f'#!/bin/sh\nexec "{sys.executable}" {args}\n')
        shim.chmod(0o755)
    env = dict(os.environ)
    env["PATH"] = f"{shims}{os.pathsep}{env.get('PATH', '')}"
    src = str(Path(parcelfit.__file__).parents[1])
    env["PYTHONPATH"] = os.pathsep.join(p for p in (src, env.get("PYTHONPATH")) if p)
    env["COLUMNS"] = "120"
    return work, env


@pytest.mark.slow
@pytest.mark.mujoco
@pytest.mark.longest
def test_every_command_of_the_user_guide_runs(tmp_path):
    work, env = _workspace(tmp_path)
    said: dict[str, str] = {}  # what each page's blocks printed, one line
    for page in guide_pages():
        for k, text in runnable(page):
            result = subprocess.run(
                ["bash", "-euo", "pipefail", "-c", text],
                cwd=work,
                env=env,
                capture_output=True,
                text=True,
                timeout=600,
            )
            assert result.returncode == 0, (
                f"{page}, block {k} failed:\n{text}\n--- stdout\n{result.stdout[-3000:]}\n"
                f"--- stderr\n{result.stderr[-3000:]}"
            )
            said[page] = said.get(page, "") + " " + " ".join(result.stdout.split())
    # what the pages promise was made
    assert (work / "my-tags.yaml").read_text().count("camera:") == 1
    assert (work / "my-dataset" / "dataset.yaml").is_file()
    assert (work / "examples" / "own-rig" / "study" / "report.html").is_file()
    _the_own_rig_tutorial_made_its_dataset_study_and_report(
        work / "examples" / "own-rig", said, env
    )


def _the_own_rig_tutorial_made_its_dataset_study_and_report(
    own: Path, said: dict[str, str], env: dict[str, str]
) -> None:
    """The "Your own rig" page, followed from scratch: a rig and a consignment file that are
    not bundled, a SYNTHETIC dataset on them in the documented format (`parcelfit synth`), the
    study with a small budget, `calibrate`, `status` and `report`."""
    import json

    import pandas as pd
    import yaml

    from parcelfit.runs import load_dataset

    rig = said["guide/rig.md"]
    assert "expected cost: 6 simulations on 2 processes" in rig  # synth
    # 6 evaluations, 1 validation, the convergence check's run and the key frames
    assert "expected cost: 9 simulations on 2 processes" in rig and "mu_d_BePa" in rig
    assert "published criteria: " in rig and "verdict: " in rig  # calibrate and report
    doc = yaml.safe_load((own / "data" / "dataset.yaml").read_text())
    assert doc["synthetic"] is True
    assert [(c["rig"], c["consignment"], c["speed_setting"]) for c in doc["test_cases"]] == [
        ("D1", "envelope", 1),
        ("D1", "envelope", 2),
    ]
    run = doc["test_cases"][0]["runs"][0]
    frame = pd.read_csv(own / "data" / run["file"])
    assert list(frame.columns) == ["t", "x", "y", "theta"] and run["transit_time"] > 0
    assert len(load_dataset(own / "data").runs()) == 6
    status = subprocess.run(
        [sys.executable, "-m", "parcelfit", "status", str(own / "study"), "--json"],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    info = json.loads(status.stdout)
    assert info["evaluations"] <= 6 and info["pending"] == 0 and info["validations"]
    assert info["study"]["name"] == "d1-envelope"
    page = (own / "study" / "report.html").read_text()
    assert "SYNTHETIC" in page and "D1/envelope/1" in page and "What the data determine" in page
