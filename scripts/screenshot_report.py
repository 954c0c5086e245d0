"""Screenshot of a report for the docs (headless Chromium).

python scripts/screenshot_report.py parcelfit-demo/report.html docs/figures/report.png
"""

from __future__ import annotations

import sys
from pathlib import Path

from parcelfit.report.browser import inspect_page, screenshot

if __name__ == "__main__":
    page, png = Path(sys.argv[1]).resolve(), Path(sys.argv[2])
    found = inspect_page(page)
    print(found)
    if found["broken"]:
        raise SystemExit(f"{found['broken']} images did not load")
    height = int(sys.argv[3]) if len(sys.argv) > 3 else 2200
    screenshot(page, png.resolve(), width=1200, height=height)
    print(f"wrote {png}")
