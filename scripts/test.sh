#!/usr/bin/env bash
# Install what the tests need and run them: Debian's Chromium (the HTML report is checked in a
# real headless browser), the Python test extras, then the linter and the test suite.
# This is the README's test command; CI (.ci/run) runs exactly this.
set -euo pipefail
cd "$(dirname "$0")/.."

if ! command -v chromium >/dev/null 2>&1; then
  SUDO=""
  if [ "$(id -u)" != 0 ] && command -v sudo >/dev/null 2>&1; then SUDO="sudo"; fi
  if command -v apt-get >/dev/null 2>&1 && { [ "$(id -u)" = 0 ] || [ -n "$SUDO" ]; }; then
    echo "installing chromium (Debian package) for the report's browser test"
    export DEBIAN_FRONTEND=noninteractive
    $SUDO apt-get install -y -q chromium >/dev/null 2>&1 \
      || { $SUDO apt-get update -q >/dev/null && $SUDO apt-get install -y -q chromium >/dev/null; }
  else
    echo "note: chromium is not installed and cannot be installed here; the browser test is skipped"
  fi
fi

python3 -m pip install -e ".[test]"
python3 -m ruff check .
# -n auto: one test process per core (xdist); pass -n 0 to run in this process only
python3 -m pytest -n auto "$@"
