#!/usr/bin/env bash
# bench/run_bench.sh BUILD_DIR — `make bench`: writes BENCHMARKS.md and docs/scaling.png.
#  1. the issues' targets on the reference scenes (bench/targets.sh; skipped without them);
#  2. `sdfprune bench` over every generated kind at the paper's size (and the reference scenes),
#     all four variants, beside the paper's Tables 1-2;
#  3. a scaling series (fluid from 100 to 1,000,000 spheres): cost against primitive count.
# Sizes are chosen to finish in minutes on a 2-core machine; naive runs over BUDGET seconds are
# estimated from samples and marked. Environment: W, H, BUDGET, MAX_COUNT (default 1000000).
set -euo pipefail
build=${1:-build}
bin="$build/sdfprune"
here=$(cd "$(dirname "$0")" && pwd)
scenes=${SDFPRUNE_SCENES:-$here/../../shared/scenes}
W=${W:-960} H=${H:-540} BUDGET=${BUDGET:-10} MAX_COUNT=${MAX_COUNT:-1000000}
work="$build/bench-work"
mkdir -p "$work" docs
log() { echo "bench: $*" >&2; }

{
  "$here/targets.sh" "$build"
  echo
  echo "## Tables 1–2 over the generated scenes (and the reference scenes)"
  echo
  echo "\`sdfprune bench\` at ${W}x${H}, discretization 256³, budget ${BUDGET} s per measurement"
  echo "(beyond it: estimated from a sample, marked ≈). Generated scenes are procedural stand-ins"
  echo "with the paper's node counts (\`sdfprune generate\`), not the paper's scenes: compare their"
  echo "ratios, not their absolute times, with the paper's columns."
  echo
} > "$work/BENCHMARKS.md"

list=()
for kind in character raccoon console gameboy car train-station camera trees car-chase city \
            crowd molecule monument fluid; do
  log "generate $kind"
  "$bin" generate "$kind" -o "$work/$kind.json" >/dev/null
  list+=("$work/$kind.json")
done
for s in molecule trees; do
  [ -f "$scenes/$s.json" ] && list+=("$scenes/$s.json")
done
log "bench over ${#list[@]} scenes"
"$bin" bench "${list[@]}" --width "$W" --height "$H" --budget-s "$BUDGET" \
  --md "$work/tables.md" -o "$work/tables.json" >&2
cat "$work/tables.md" >> "$work/BENCHMARKS.md"

series=()
n=100
while [ "$n" -le "$MAX_COUNT" ]; do
  log "generate fluid --count $n"
  "$bin" generate fluid --count "$n" -o "$work/fluid-$n.json" >/dev/null
  series+=("$work/fluid-$n.json")
  n=$((n * 10))
done
log "scaling series"
"$bin" bench "${series[@]}" --variants ours,naive --width 480 --height 270 --budget-s "$BUDGET" \
  --md "$work/scaling.md" --plot docs/scaling.png -o "$work/scaling.json" >&2
{
  echo
  echo "## Scaling: fluid from 100 to $MAX_COUNT spheres"
  echo
  echo "![cost against primitive count](docs/scaling.png)"
  echo
  cat "$work/scaling.md"
} >> "$work/BENCHMARKS.md"
mv "$work/BENCHMARKS.md" BENCHMARKS.md
log "wrote BENCHMARKS.md and docs/scaling.png"
