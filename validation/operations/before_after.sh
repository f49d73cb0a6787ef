#!/usr/bin/env bash
# before_after.sh TREE OUTDIR [--only ID ...]: issue 13's scenarios against one source tree,
# one result line per scenario on stdout (details on stderr, logs and results.json in OUTDIR).
# The work is done by before_after.py beside this file; see its docstring.
set -u
if [ $# -lt 2 ]; then
    echo "usage: $0 TREE OUTDIR [--only ID ...]" >&2
    exit 2
fi
here=$(cd "$(dirname "$0")" && pwd)
py=${RLS_PYTHON:-/work/main/.venv/bin/python}
export PYTHONDONTWRITEBYTECODE=1 ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-191}
unset PYTHONPATH
exec "$py" "$here/before_after.py" "$@"
