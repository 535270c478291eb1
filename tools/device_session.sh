#!/usr/bin/env bash
# tools/device_session.sh OUT — what a lent GPU is wanted for, in priority order, as one command
# for the device tool's `run` (whose command line holds 2,000 characters). A session has a few
# minutes of device time and at most 600 s a command, so each part runs under its own limit: a
# part that runs out is stopped, what it printed so far is kept, and the next part starts.
# Run in the repo's root on the device machine, with .dev/ and .gl/ carried (made here by
# tools/device_pack.sh; BASELINE=PATH packs a build to compare with as build/sdfprune.base):
#   source tools/device_env.sh && bash tools/device_session.sh "$OUT"
# It also runs here, on lavapipe, as a check of itself (GRID=32 and SDFPRUNE_GPU_SCENES="trees"
# keep it short).
# The parts, and their limits in seconds (STEPS_S, TESTS_S, TABLE_S; 0 skips a part):
#   1. steps (240): bench/gpu_steps.sh, ROUNDS=2, this build (new) against build/sdfprune.base
#      (base, where there is one) and VARIANTS (LABEL=COMMAND words: by default the settings
#      that turn off the changes of the stops since the last GPU run, so that one run times
#      each against the rest). Lines in OUT/steps.txt, each run's JSON in OUT/steps/.
#   2. tests (150): the Gpu, GpuLayout and GpuCli tests, gtest's XML in OUT/gpu-tests.xml.
#   3. table (180): bench/gpu.sh with the million-sphere fluid (FLUID_COUNTS, default 1000000):
#      markdown in OUT/gpu-table.md, results in OUT/gpu-results.json (bench/gpu-results.json's
#      format, for committing after a look).
# OUT/session.log says when each part started, how it ended (its exit status: 124 where its
# limit stopped it) and how many seconds it took.
set -uo pipefail
out=${1:?usage: tools/device_session.sh OUT}
mkdir -p "$out" || exit 2
cd "$(dirname "$0")/.." || exit 2
[ -x build/sdfprune ] && [ -x build/sdfprune_tests ] || {
  echo "device_session: build/sdfprune or build/sdfprune_tests missing (source tools/device_env.sh)" >&2
  exit 2
}
bin=build/sdfprune
default_variants=(
  "chainsoff=env SDFPRUNE_VULKAN_WIDE_CHAINS=0 $bin"
  "widedealt=env SDFPRUNE_VULKAN_WIDE_TAKE=0 $bin"
  "dealt=env SDFPRUNE_VULKAN_TAKE=0 SDFPRUNE_VULKAN_WIDE_TAKE=0 $bin"
)
if [ -n "${VARIANTS:-}" ]; then
  read -r -a variants <<<"$VARIANTS"  # (words: a variant with spaces needs the default list)
else
  variants=("${default_variants[@]}")
fi
base=()
[ -x build/sdfprune.base ] && base=("base=build/sdfprune.base")
log="$out/session.log"
: >"$log"

# part NAME LIMIT COMMAND...: COMMAND under LIMIT seconds (its process group stopped then),
# its output into OUT/NAME.txt as it comes; a line in the log either way.
part() {
  local name=$1 limit=$2
  shift 2
  if [ "$limit" = 0 ]; then
    echo "$(date -u +%T) $name skipped" >>"$log"
    return
  fi
  local start=$SECONDS
  echo "$(date -u +%T) $name started (limit $limit s): $*" >>"$log"
  timeout --kill-after=10 "$limit" "$@" >"$out/$name.txt" 2>&1
  local rc=$?
  echo "$(date -u +%T) $name ended: exit $rc after $((SECONDS - start)) s" >>"$log"
}

$bin stats builtin:demo --grid 16 --backend vulkan --json 2>&1 | tail -n 1 |
  sed -E 's/.*"device":"([^"]*)".*/device: \1/' >>"$log"
part steps "${STEPS_S:-240}" env ROUNDS="${ROUNDS:-2}" SAVE="$out/steps" \
  bash bench/gpu_steps.sh new=$bin "${base[@]}" "${variants[@]}"
part tests "${TESTS_S:-150}" build/sdfprune_tests --gtest_filter='Gpu*' \
  --gtest_output="xml:$out/gpu-tests.xml"
part table "${TABLE_S:-180}" env SDFPRUNE_GPU_FLUID_COUNTS="${FLUID_COUNTS-1000000}" \
  bash bench/gpu.sh build "$out/gpu-results.json"
[ -f "$out/table.txt" ] && grep -v '^bench: ' "$out/table.txt" >"$out/gpu-table.md"
cat "$log"
