#!/usr/bin/env bash
# The dashboard's plotting library (uPlot, MIT) from the npm registry, at the exact version and
# integrity hash of rls_uncertainty/dashboard/package-lock.json, into
# rls_uncertainty/dashboard/node_modules/ (git-ignored; served from this machine by
# `rls-uncertainty dashboard`, never from a CDN). Needs npm (Debian/Ubuntu: apt-get install
# npm); runs no package scripts. Idempotent: does nothing when the installed files match the lock.
# Meant to be called from scripts/setup.sh.
set -euo pipefail
cd "$(dirname "$0")/../rls_uncertainty/dashboard"
stamp=node_modules/.rls_installed
want=$(sha256sum package-lock.json | cut -d' ' -f1)
if [ -f node_modules/uplot/dist/uPlot.iife.min.js ] && [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
  exit 0
fi
if ! command -v npm >/dev/null 2>&1; then
  echo "setup_dashboard: npm not found; install it (apt-get install npm) and run this again: the dashboard needs uPlot" >&2
  exit 1
fi
echo "setup_dashboard: installing uPlot from the npm registry (package-lock.json)" >&2
npm ci --ignore-scripts --no-audit --no-fund --omit=dev --loglevel=error >&2
echo "$want" > "$stamp"
