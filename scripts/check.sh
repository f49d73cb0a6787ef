#!/usr/bin/env bash
# Lint and type checks: ruff over every Python file of the checkout, mypy over the package
# (configuration and the reasons for it in pyproject.toml; versions pinned in
# requirements-dev.txt, installed by scripts/setup.sh). Both always run, so one pass shows
# every finding; exits non-zero if either reports anything. Run by .ci/run before pytest.
set -uo pipefail
cd "$(dirname "$0")/.."
py=.venv/bin/python
if [ ! -x "$py" ]; then
  echo "check: $py not found; run bash scripts/setup.sh first" >&2
  exit 2
fi
status=0
echo "check: ruff $("$py" -m ruff --version | cut -d' ' -f2)" >&2
"$py" -m ruff check --no-fix . || status=1
echo "check: mypy $("$py" -m mypy --version | cut -d' ' -f2)" >&2
"$py" -m mypy || status=1
if [ "$status" -ne 0 ]; then
  echo "check: findings above (ruff check --fix repairs the ones marked [*])" >&2
fi
exit "$status"
