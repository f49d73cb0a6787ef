#!/usr/bin/env bash
# Headless Chromium for the dashboard's browser tests (test/test_dashboard_browser.py), from
# Debian's package (the tests drive /usr/bin/chromium with Playwright and never download a
# browser of their own). Installs with apt only when it is missing and this runs as root;
# otherwise says what to do. Idempotent. The tests skip with the reason when no browser is
# found, and fail instead under RLS_REQUIRE_BROWSER=1 (set by .ci/run).
set -euo pipefail
if command -v chromium >/dev/null 2>&1; then
  exit 0
fi
if [ "$(id -u)" -ne 0 ]; then
  echo "setup_browser: chromium not found; install it (sudo apt-get install chromium) to run the browser tests" >&2
  exit 0
fi
if ! command -v apt-get >/dev/null 2>&1; then
  echo "setup_browser: chromium not found and no apt-get here; install a Chromium as /usr/bin/chromium" >&2
  exit 0
fi
echo "setup_browser: installing chromium (Debian package) for the browser tests" >&2
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq >/dev/null
apt-get install -y -qq --no-install-recommends chromium fonts-dejavu-core >/dev/null
command -v chromium >/dev/null 2>&1 || { echo "setup_browser: chromium installation failed" >&2; exit 1; }
