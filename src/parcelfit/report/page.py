"""The frame of parcelfit's HTML pages (the report, a prediction's page): the Jinja2 templates, the
style sheet and the Content-Security-Policy, figures and images embedded as data URIs, files named
by stored data read only from inside their folder, the sections in page order, and the page
written atomically."""

from __future__ import annotations

import base64
import io
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jinja2
from markupsafe import Markup
from matplotlib.figure import Figure

from parcelfit.atomic import write_text_atomic
from parcelfit.errors import ParcelfitError
from parcelfit.progress import ProgressCallback, ProgressEvent

# The report promises to be script-free and to fetch nothing: the page forbids every script,
# frame, font and connection, and allows only embedded (data:) images and its own inline styles.
CONTENT_SECURITY_POLICY = (
    "default-src 'none'; img-src data:; style-src 'unsafe-inline'; base-uri 'none'; "
    "form-action 'none'"
)
TEMPLATES = jinja2.Environment(
    loader=jinja2.PackageLoader("parcelfit.report", "templates"),
    autoescape=True,
    undefined=jinja2.StrictUndefined,
    trim_blocks=True,
    lstrip_blocks=True,
)

CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;max-width:1100px;margin:2em auto;
padding:0 1em;color:#222;line-height:1.45}
h1{margin-bottom:.2em}h2{border-bottom:2px solid #ddd;padding-bottom:.2em;margin-top:2em}
.synthetic{background:#fff3cd;border:1px solid #e0b000;padding:.6em 1em;border-radius:6px}
.verdict{font-size:1.15em;padding:.7em 1em;border-radius:6px;margin:1em 0}
.pass{background:#e3f6e8;border:1px solid #27ae60}.fail{background:#fdecea;border:1px solid #e74c3c}
.incomplete{background:#fff8e1;border:1px solid #e0a000}.verdict ul{margin:.3em 0;font-size:.9em}
table{border-collapse:collapse;margin:.8em 0;font-size:.92em}
th,td{border:1px solid #ccc;padding:.25em .6em;text-align:right}th{background:#f3f3f3}
td:first-child,th:first-child{text-align:left}
img{max-width:100%;height:auto;display:block;margin:.6em 0}
.grid{display:flex;flex-wrap:wrap;gap:1%}.grid img{max-width:49%}
.note{color:#555;font-size:.92em}.ok{color:#1e8449;font-weight:600}.bad{color:#c0392b;font-weight:600}
.warn{color:#9a6700;font-weight:600}
code{background:#f4f4f4;padding:0 .2em}
"""

# what a missing stored result means, and how to write it (said once, at the top of the page)
NO_RESULTS = (
    "This study folder has no stored results (results.json): it was written by a parcelfit "
    "before the calibration stored them, or the study stopped before it validated. The "
    "sections that need them say so; nothing is recomputed here. Run `parcelfit calibrate` "
    "again on the same study file and folder to write them: a finished study then only writes "
    "its results, figures and key frames (no evaluation is simulated again)."
)
NOT_STORED = "Not stored in this study folder (see the note at the top of the page)."


def figure_html(fig: Figure, alt: str, dpi: int = 100) -> Markup:
    """A matplotlib figure as an embedded PNG ``<img>``."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return png_html(buf.getvalue(), alt)


def png_html(data: bytes, alt: str, mime: str = "image/png") -> Markup:
    """Image bytes (PNG unless ``mime`` says otherwise) as an embedded ``<img>``."""
    b64 = base64.b64encode(data).decode("ascii")
    return Markup('<img src="data:{};base64,{}" alt="{}">').format(mime, b64, alt)


# The files the report embeds or reads are named by stored data (``results.json``'s key frames)
# or found by name in the folders it is given; a study folder may come from someone else. A file
# is read only when its resolved path (symbolic links followed) lies inside the resolved folder,
# so neither ``../../secret.txt``, an absolute path nor a link leading out is ever opened; the
# page says which file it refused. Embedded images must also be what they claim (PNG, GIF) and
# at most `MAX_EMBED_BYTES`.
MAX_EMBED_BYTES = 64 * 1024 * 1024
_MAGIC = {"image/png": (b"\x89PNG\r\n\x1a\n",), "image/gif": (b"GIF87a", b"GIF89a")}


@dataclass(frozen=True)
class Refused:
    """Why a file named by stored data or found in a folder was not read."""

    name: str
    reason: str

    def __str__(self) -> str:
        return f"{self.name} is not embedded: {self.reason}."


def inside(folder: Path, name: object, what: str = "the study folder") -> Path | Refused | None:
    """The file ``name`` (relative to ``folder``, as stored) resolved, when it lies inside the
    resolved ``folder`` and is a regular file; `Refused` (saying why) when it leads out of it
    or is not a file name; None when it does not exist. Never opens the file."""
    shown = str(name)
    if not isinstance(name, str) or not name or "\0" in name:
        return Refused(shown, "not a file name")
    try:
        base = folder.resolve(strict=True)
        path = (folder / name).resolve()
        if not path.is_relative_to(base):
            return Refused(shown, f"outside {what}")
        return path if path.is_file() else None
    except (OSError, RuntimeError, ValueError):  # a loop of links, an unreadable folder
        return Refused(shown, "not readable")


def embeddable(folder: Path, name: object, mime: str, what: str) -> bytes | Refused | None:
    """The bytes of a file that `inside` accepts and that is a ``mime`` image (PNG or GIF) of
    at most `MAX_EMBED_BYTES`; `Refused` or None (missing) otherwise."""
    path = inside(folder, name, what)
    if not isinstance(path, Path):
        return path
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
            if not head.startswith(_MAGIC[mime]):
                return Refused(str(name), f"not a {mime.split('/')[1].upper()} image")
            if fh.seek(0, io.SEEK_END) > MAX_EMBED_BYTES:
                return Refused(str(name), f"larger than {MAX_EMBED_BYTES >> 20} MiB")
            fh.seek(0)
            return fh.read()
    except OSError:
        return Refused(str(name), "not readable")


@dataclass(frozen=True)
class Section:
    """One heading of the page: its template (``templates/sections/KIND.html.j2``), title,
    anchor and the values the template shows."""

    kind: str
    title: str
    anchor: str
    data: Any


@dataclass
class Page:
    """The sections in page order; announces each as it is made."""

    progress: ProgressCallback
    sections: list[Section] = field(default_factory=list)

    def start(self, title: str) -> str:
        """Announce a section as its making starts; returns its title."""
        self.progress(ProgressEvent("report", title))
        return title

    def add(self, kind: str, title: str, anchor: str, data: Any) -> None:
        """Append a made section."""
        self.sections.append(Section(kind, title, anchor, data))


def write_page(target: Path, doc: str) -> None:
    """Write the page ``doc`` to ``target`` atomically (a temporary file renamed); nothing is
    left behind on failure."""
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(target, doc)
    except OSError as exc:
        raise ParcelfitError(
            f"cannot write the report ({exc.strerror or exc})",
            file=target,
            fix="choose a writable --out",
        ) from None


__all__ = [
    "CONTENT_SECURITY_POLICY",
    "CSS",
    "MAX_EMBED_BYTES",
    "NOT_STORED",
    "NO_RESULTS",
    "TEMPLATES",
    "Page",
    "Refused",
    "Section",
    "embeddable",
    "figure_html",
    "inside",
    "png_html",
    "write_page",
]
