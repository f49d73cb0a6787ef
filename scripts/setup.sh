#!/usr/bin/env bash
# Create (or refresh) the project's virtual environment in .venv and install everything:
# the ROS 2 Jazzy stack from the package index, the numerical and bag libraries, test, lint and
# type-check tools, and this package itself (editable). Idempotent and fast when nothing
# changed (a stamp holds the hash of the requirement files and the pin mode); safe to run
# before every command. Needs no git checkout: it works the same in a copied or unpacked tree.
#
# Versions: by default the exact, tested set in constraints.txt (pip install -c), so every
# machine computes with the same numpy, scipy and OpenBLAS. The ranges stay in
# requirements*.txt. To install (upgrade to) the newest versions those ranges allow instead:
#   bash scripts/setup.sh --unpinned        (or RLS_UNPINNED=1 bash scripts/setup.sh)
# A later run without the option goes back to the pinned versions.
set -euo pipefail
cd "$(dirname "$0")/.."

pinned=1
[ "${RLS_UNPINNED:-0}" = "0" ] || pinned=0
for arg in "$@"; do
  case "$arg" in
    --unpinned) pinned=0 ;;
    *) echo "setup: unknown option $arg (the only one is --unpinned)" >&2; exit 2 ;;
  esac
done

pick_python() {
  for py in "${PYTHON:-}" python3.12 python3.11 python3; do
    [ -n "$py" ] || continue
    if command -v "$py" >/dev/null 2>&1 && "$py" -c 'import sys; sys.exit(0 if sys.version_info[:2] in ((3, 11), (3, 12)) else 1)' 2>/dev/null; then
      echo "$py"; return 0
    fi
  done
  echo "setup: need CPython 3.11 or 3.12 (ROS 2 Jazzy wheels exist only for those)" >&2
  return 1
}

if [ ! -x .venv/bin/python ]; then
  py=$(pick_python)
  echo "setup: creating .venv with $($py --version)" >&2
  "$py" -m venv .venv
fi
stamp=.venv/.installed
versions=(--upgrade)
[ "$pinned" = 1 ] && versions=(-c constraints.txt)
want=$( { echo "pinned=$pinned"; cat requirements.txt requirements-dev.txt constraints.txt setup.py setup.cfg package.xml; } \
  | sha256sum | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  if [ "$pinned" = 1 ]; then
    echo "setup: installing the tested versions (constraints.txt) into .venv" >&2
  else
    echo "setup: installing the newest versions requirements*.txt allow into .venv (unpinned)" >&2
  fi
  .venv/bin/python -m pip install --quiet --disable-pip-version-check "${versions[@]}" -r requirements-dev.txt 2>&1 \
    | grep -v "is ignored: it is neither a file nor a directory" >&2 || true
  .venv/bin/python -m pip install --quiet --disable-pip-version-check --no-deps -e . 2>&1 \
    | grep -v "is ignored: it is neither a file nor a directory" >&2 || true
  .venv/bin/python -c "import numpy, scipy, yaml, rosbags, mcap, rclpy, pytest, ruff, mypy" \
    || { echo "setup: installation incomplete" >&2; exit 1; }
  echo "$want" > "$stamp"
fi

# The dashboard's plotting library (uPlot, from the npm registry at the version of
# rls_uncertainty/dashboard/package-lock.json). Without npm everything else still works and the
# dashboard says what is missing; CI (RLS_REQUIRE_BROWSER=1, set by .ci/run) requires it and
# Debian's Chromium for the browser tests (scripts/setup_browser.sh, apt when run as root).
if ! bash scripts/setup_dashboard.sh; then
  [ "${RLS_REQUIRE_BROWSER:-0}" = "0" ] || exit 1
  echo "setup: continuing without the dashboard's assets" >&2
fi
if [ "${RLS_REQUIRE_BROWSER:-0}" != "0" ]; then
  bash scripts/setup_browser.sh
fi
