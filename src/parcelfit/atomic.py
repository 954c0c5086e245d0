"""Writing a file so that a crash never leaves half of it under its final name."""

from __future__ import annotations

import os
from pathlib import Path


def write_text_atomic(path: Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` through a temporary file beside it, renamed into place
    once complete; on failure the temporary file is removed and the error raised (an `OSError`
    naming ``path``, as a full disk gives none). Returns path."""
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")  # per process: writers never collide
    try:
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(path)
    except OSError as exc:
        if exc.filename is None or exc.filename == str(tmp):
            exc.filename = str(path)
        raise
    finally:
        tmp.unlink(missing_ok=True)
    return path
