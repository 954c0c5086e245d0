"""Moved to `parcelfit.study.calibration`; this path stays for existing imports (the same module object)."""

import importlib
import sys

sys.modules[__name__] = importlib.import_module("parcelfit.study.calibration")
