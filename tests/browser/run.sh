#!/usr/bin/env bash
# run.sh BUILD_DIR — the viewer's browser tests (viewer.test.js) in Debian's headless Chromium.
# Installs playwright-core and pngjs from npm (pinned in package-lock.json) on first use. When
# Chromium or npm is missing, prints SKIPPED with the reason and exits 0; never reports a pass
# that did not run.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
build="$(cd "${1:?usage: run.sh BUILD_DIR}" && pwd)"
chromium="${CHROMIUM:-/usr/bin/chromium}"
if [ ! -x "$chromium" ]; then
  echo "browser tests: SKIPPED: $chromium not found (make setup installs Debian's chromium)"
  exit 0
fi
if ! command -v node >/dev/null || ! command -v npm >/dev/null; then
  echo "browser tests: SKIPPED: node and npm are needed to drive Chromium (playwright-core)"
  exit 0
fi
if [ ! -d "$here/node_modules/playwright-core" ] || [ ! -d "$here/node_modules/pngjs" ]; then
  if ! (cd "$here" && npm ci --no-audit --no-fund --loglevel=error); then
    echo "browser tests: SKIPPED: npm ci could not install playwright-core (no npm registry?)"
    exit 0
  fi
fi
cd "$here"
SDFPRUNE_CLI="$build/sdfprune" CHROMIUM="$chromium" timeout 300 \
  node --test --test-reporter=spec viewer.test.js
