#!/usr/bin/env bash
# Create (or refresh) the project's virtual environment in .venv and install everything:
# the ROS 2 Jazzy stack from the package index, the numerical and bag libraries, test, lint and
# type-check tools, and this package itself (editable). Idempotent; safe to run before every
# command. Needs no git checkout: it works the same in a copied or unpacked tree.
set -euo pipefail
cd "$(dirname "$0")/.."

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
want=$(cat requirements.txt requirements-dev.txt setup.py setup.cfg | sha256sum | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "setup: installing dependencies into .venv" >&2
  .venv/bin/python -m pip install --quiet --disable-pip-version-check -r requirements-dev.txt 2>&1 \
    | grep -v "is ignored: it is neither a file nor a directory" >&2 || true
  .venv/bin/python -m pip install --quiet --disable-pip-version-check --no-deps -e . 2>&1 \
    | grep -v "is ignored: it is neither a file nor a directory" >&2 || true
  .venv/bin/python -c "import numpy, scipy, yaml, rosbags, mcap, rclpy, pytest, ruff, mypy" \
    || { echo "setup: installation incomplete" >&2; exit 1; }
  echo "$want" > "$stamp"
fi

# ---- dashboard assets (merge into the new setup): uPlot from the npm registry at the exact
# version of rls_uncertainty/dashboard/package-lock.json (rls-uncertainty dashboard serves it).
bash scripts/setup_dashboard.sh
