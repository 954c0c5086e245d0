"""The HTML report of a calibration (see `parcelfit.report.html` for what it holds)."""

from parcelfit.report.html import build_report, verdict_text

__all__ = ["build_report", "verdict_text"]
