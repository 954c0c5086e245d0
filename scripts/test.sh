#!/usr/bin/env bash
# The README's test command; CI (.ci/run) runs exactly this.
#
# 1. The base install, as a newcomer gets it: a fresh virtual environment, `pip install -e .`
#    with no extras, then `parcelfit --help` and the README's main job in its quick form
#    (`parcelfit demo --quick`). An import that only an extra brings in fails here.
# 2. Only then the test extras into that same environment: the linter, the dependency check
#    (deptry: every import in src/ is a declared dependency), the test suite, and the
#    documentation site (mkdocs build --strict: a broken link or a missing page fails).
# Debian's Chromium is installed first where possible (the HTML report is checked in a real
# headless browser).
#
# Arguments are passed to pytest (e.g. `-m "not slow"`, `-n 0`). PARCELFIT_SKIP_BASE_CHECK=1
# skips step 1's demo (the fresh environment is still made); for quick local runs only.
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

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
venv="$work/venv"
py="$venv/bin/python"

echo "== base install (no extras) into a fresh virtual environment"
python3 -m venv "$venv"
"$py" -m pip install -q --upgrade pip
"$py" -m pip install -q -e .
"$venv/bin/parcelfit" --help >/dev/null
echo "parcelfit --help: ok"
if [ "${PARCELFIT_SKIP_BASE_CHECK:-0}" != 1 ]; then
  start=$(date +%s)
  "$venv/bin/parcelfit" demo --quick --no-animation --out "$work/demo" | tee "$work/demo.log"
  test -s "$work/demo/report.html"
  echo "parcelfit demo --quick: ok in $(( $(date +%s) - start )) s, report written"
  # the suite's demo test checks this run instead of running the same minutes again
  export PARCELFIT_DEMO_QUICK_DIR="$work/demo" PARCELFIT_DEMO_QUICK_LOG="$work/demo.log"
fi

echo "== test extras, lint, dependency check, tests"
"$py" -m pip install -q -e ".[test]"
"$py" -m ruff check .
"$py" -m deptry src
# -n auto: one test process per core (xdist); pass -n 0 to run in this process only
"$py" -m pytest -n auto --durations=25 "$@"

echo "== documentation site (mkdocs build --strict)"
NO_MKDOCS_2_WARNING=1 "$py" -m mkdocs build --strict --quiet --site-dir "$work/site"
echo "mkdocs build --strict: ok"
