#!/usr/bin/env bash
# bench/python.sh BUILD_DIR — the Python package's targets (bench/python_bench.py), run with the
# package installed in BUILD_DIR/pyenv (make python) against BUILD_DIR/sdfprune.
set -euo pipefail
build=${1:-build}
here=$(cd "$(dirname "$0")" && pwd)
exec "$build/pyenv/bin/python" "$here/python_bench.py" --cli "$(cd "$build" && pwd)/sdfprune"
