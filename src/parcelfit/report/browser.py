"""Render a local HTML file in headless Chromium (Debian's ``chromium``): a screenshot, and a
check that the page loads and every image decodes (a harness page loads the file in an iframe
and writes what it found into its own DOM, which ``--dump-dom`` prints)."""

from __future__ import annotations

import html
import json
import os
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--hide-scrollbars",
]

HARNESS = """<!DOCTYPE html><html><head><meta charset="utf-8"></head><body>
<iframe id="f" src="{src}" style="width:1200px;height:2000px"></iframe>
<pre id="out">pending</pre>
<script>
document.getElementById("f").addEventListener("load", () => {{
  const doc = document.getElementById("f").contentDocument;
  const imgs = Array.from(doc.images);
  const result = {{
    title: doc.title,
    headings: Array.from(doc.querySelectorAll("h2")).map(h => h.id),
    images: imgs.length,
    broken: imgs.filter(i => !(i.complete && i.naturalWidth > 0)).length,
    height: doc.documentElement.scrollHeight,
  }};
  document.getElementById("out").textContent = "RESULT" + JSON.stringify(result) + "END";
}});
</script></body></html>"""


def chromium() -> str | None:
    """The Chromium executable, or None."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


def _run(args: list[str], timeout: float = 120) -> subprocess.CompletedProcess[str]:
    with tempfile.TemporaryDirectory() as profile:
        return subprocess.run(
            [chromium() or "chromium", *FLAGS, f"--user-data-dir={profile}", *args],
            capture_output=True,
            text=True,
            timeout=timeout,
            env={**os.environ, "DBUS_SESSION_BUS_ADDRESS": "disabled:"},
        )


def inspect_page(page: Path) -> dict:
    """Load ``page`` in Chromium; report its title, section ids, images and broken images."""
    harness = page.parent / "_harness.html"
    harness.write_text(HARNESS.format(src=page.name), encoding="utf-8")
    try:
        proc = _run(
            [
                "--allow-file-access-from-files",
                "--virtual-time-budget=15000",
                "--dump-dom",
                harness.as_uri(),
            ]
        )
    finally:
        harness.unlink()
    found = re.search(r"RESULT(.*?)END", proc.stdout, re.S)
    if not found:
        raise AssertionError(f"the page did not report back; stderr: {proc.stderr[-2000:]}")
    return json.loads(html.unescape(found.group(1)))  # --dump-dom prints the text as HTML


def screenshot(page: Path, png: Path, width: int = 1200, height: int = 3000) -> Path:
    """A PNG of ``page`` rendered at ``width`` x ``height`` pixels."""
    proc = _run([f"--window-size={width},{height}", f"--screenshot={png}", page.as_uri()])
    if not png.is_file():
        raise AssertionError(f"no screenshot; stderr: {proc.stderr[-2000:]}")
    return png
