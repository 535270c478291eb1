#!/usr/bin/env bash
# make run: the main job on the built-in demo scene (no scene file needed).
set -euo pipefail
build=${1:-build}
bin="$build/sdfprune"
echo "== sdfprune info builtin:demo"
"$bin" info builtin:demo
