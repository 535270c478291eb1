#!/usr/bin/env bash
# bench/targets.sh BUILD_DIR — measures the issues' targets on the reference scenes and prints
# BENCHMARKS.md (markdown) on stdout: pruning quality (the paper's Table 2 metric), pruning time
# and memory, tracing and discretization speed-ups over the naive full-tree evaluation (same
# binary, same evaluator, same threads, same image). Needs ../shared/scenes or $SDFPRUNE_SCENES.
# Environment: W, H (image for the speed-up, default 960x540), RES (discretization, default 256),
# ROUNDS (runs of each pruning-time row, default 5: the fastest and the median are reported).
set -euo pipefail
build=${1:-build}
bin="$build/sdfprune"
scenes=${SDFPRUNE_SCENES:-$(dirname "$0")/../../shared/scenes}
W=${W:-960} H=${H:-540} RES=${RES:-256} ROUNDS=${ROUNDS:-5}
if ! [[ $ROUNDS =~ ^[1-9][0-9]*$ ]]; then
  echo "bench/targets.sh: ROUNDS must be a positive integer, not '$ROUNDS'" >&2
  exit 2
fi
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
log() { echo "bench: $*" >&2; }
field() { sed -E "s/.*\"$2\":\"?([^,\"}]*)\"?.*/\1/" <<<"$1"; }
calc() { awk "BEGIN { printf \"$1\n\", $2 }"; }

if [ ! -f "$scenes/molecule.json" ]; then
  log "reference scenes not found in $scenes (set SDFPRUNE_SCENES); nothing to measure"
  exit 0
fi

cpu=$(sed -n 's/^model name[^:]*: //p' /proc/cpuinfo | head -n 1)
mem=$(awk '/MemTotal/ { printf "%.0f GiB", $2 / 1048576 }' /proc/meminfo)
echo "# sdfprune benchmarks"
echo
echo "Measured by \`make bench\` (bench/targets.sh) on $(date -u +%Y-%m-%d): $cpu, $(nproc) cores,"
echo "$mem RAM, $(. /etc/os-release; echo "$PRETTY_NAME"), $(c++ --version | head -n 1)."
echo "All threads in use. Pruning times are the fastest of $ROUNDS runs, with their median; other"
echo "times are one run each on a shared machine: compare ratios within a"
echo "table, not absolute times across machines. The paper's figures (Barbier et al. 2025,"
echo "Tables 1–2, laptop RTX 4060) are copied from ../shared/paper for comparison."
echo
echo "## Pruning quality at 256³ (Table 2 metric: active primitives per cell, far-field = 1)"
echo
echo "| scene | bounds | active avg ± std | max | near-field cells | prims per near cell | tape avg / max (nodes) | paper (ours) |"
echo "|---|---|---|---|---|---|---|---|"
for s in molecule trees; do
  case $s in molecule) paper="1.12 ± 0.98, 62";; trees) paper="1.10 ± 0.97, 36";; esac
  for b in lipschitz interval refined; do
    case $b in lipschitz) flag=--lipschitz-bounds;; interval) flag="--refine 1";; refined) flag="";; esac
    log "stats $s ($b)"
    j=$("$bin" stats "$scenes/$s.json" $flag --json | tail -n 1)
    printf "| %s | %s | %.4f ± %.3f | %s | %s (%.2f %%) | %.2f | %.2f / %s | %s |\n" "$s" "$b" \
      "$(field "$j" active_avg)" "$(field "$j" active_std)" "$(field "$j" active_max)" \
      "$(field "$j" near_field_cells)" "$(calc '%.6f' "100 * $(field "$j" near_field_cells) / $(field "$j" cells)")" \
      "$(field "$j" near_field_active_avg)" "$(field "$j" tape_avg)" "$(field "$j" tape_max)" "$paper"
  done
done
echo
echo "\`lipschitz\`: the paper's rule (centre ± L·R). \`interval\` (\`--refine 1\`): the same rule on"
echo "exact ranges of primitives over the cell box (similarity maps), operator ranges from their"
echo "operands' ranges, and the far-field test on the root's range. \`refined\` (the default): in"
echo "addition, finest cells decided again over their 3³ sub-boxes (see README, *Pruning*)."
echo
echo "## Pruning time and memory at 256³"
echo
echo "| scene | levels | prune time | tape words visited | peak in pruning buffers | pruned grid | process peak RSS | paper T_p / M_p |"
echo "|---|---|---|---|---|---|---|---|"
for s in molecule trees; do
  case $s in molecule) paper="8.9 ms / 1.47 GB (GPU)";; trees) paper="2.73 ms / 0.64 GB (GPU)";; esac
  for f in "4" "2" "4 --refine 1"; do
    log "prune $s factor $f ($ROUNDS runs)"
    times=()
    for ((r = 0; r < ROUNDS; r++)); do
      j=$("$bin" stats "$scenes/$s.json" --factor $f --json | tail -n 1)
      times+=("$(field "$j" prune_ms)")
    done
    sorted=$(printf '%s\n' "${times[@]}" | sort -g)
    fastest=$(head -n 1 <<<"$sorted")
    median=$(sed -n "$(( (ROUNDS + 1) / 2 ))p" <<<"$sorted")
    printf "| %s | %s%s | %.0f ms (median %.0f) | %s | %.1f MB | %.1f MB | %.1f MB | %s |\n" "$s" "$(field "$j" levels)" \
      "$([ "$(field "$j" refine)" = 1 ] && echo ", no refinement")" \
      "$fastest" "$median" "$(field "$j" tape_words_visited)" \
      "$(calc '%.3f' "$(field "$j" prune_peak_bytes) / 1e6")" "$(calc '%.3f' "$(field "$j" tape_bytes) / 1e6")" \
      "$(calc '%.3f' "$(field "$j" peak_rss_bytes) / 1e6")" "$paper"
  done
done
echo
echo "## Sphere tracing, ${W}x${H}, one primary + one shadow ray per pixel"
echo
echo "| scene | pruned: prune + trace | naive trace | trace speed-up | incl. pruning | node evals / pixel (pruned vs naive) | steps / pixel | paper speed-up |"
echo "|---|---|---|---|---|---|---|---|"
for s in molecule trees; do
  case $s in molecule) paper="×86";; trees) paper="×20";; esac
  log "render $s pruned"
  p=$("$bin" render "$scenes/$s.json" -o "$tmp/$s.png" --width $W --height $H --json --quiet | tail -n 1)
  log "render $s naive"
  n=$("$bin" render "$scenes/$s.json" -o "$tmp/${s}_naive.png" --width $W --height $H --method naive --json --quiet | tail -n 1)
  pt=$(field "$p" trace_ms); pp=$(field "$p" prune_ms); nt=$(field "$n" trace_ms)
  printf "| %s | %.0f + %.0f ms | %.0f ms | ×%.1f | ×%.1f | %.1f vs %.0f | %.2f vs %.2f | %s |\n" "$s" "$pp" "$pt" "$nt" \
    "$(calc '%.3f' "$nt / $pt")" "$(calc '%.3f' "$nt / ($pt + $pp)")" "$(field "$p" evals_avg)" "$(field "$n" evals_avg)" \
    "$(field "$p" steps_avg)" "$(field "$n" steps_avg)" "$paper"
done
echo
echo "## Discretization of molecule at ${RES}³ (the paper's T_d setting)"
echo
echo "| method | prune | evaluation | total | evaluation speed-up | prune + evaluation speed-up | paper |"
echo "|---|---|---|---|---|---|---|"
log "discretize molecule pruned"
p=$("$bin" discretize "$scenes/molecule.json" -o "$tmp/m.npy" --res $RES --json --quiet | tail -n 1)
log "discretize molecule naive (slow)"
n=$("$bin" discretize "$scenes/molecule.json" -o "$tmp/n.npy" --res $RES --method naive --json --quiet | tail -n 1)
pe=$(field "$p" eval_ms); pp=$(field "$p" prune_ms); ne=$(field "$n" eval_ms)
printf "| naive | – | %.0f ms | %.0f ms | ×1 | ×1 | 841.65 ms |\n" "$ne" "$ne"
printf "| pruned (\`--refine %s\`, the default) | %.0f ms | %.1f ms | %.0f ms | ×%.0f | ×%.0f | 8.9 + 1.48 ms: ×569 / ×81 |\n" "$(field "$p" refine)" "$pp" "$pe" \
  "$(calc '%.3f' "$pp + $pe")" "$(calc '%.3f' "$ne / $pe")" "$(calc '%.3f' "$ne / ($pp + $pe)")"
echo
echo "## Full 1920x1080 renders (pruned, wall time of the whole command)"
echo
echo "| scene | shading | wall time | prune | trace |"
echo "|---|---|---|---|---|"
for s in molecule trees; do
  for sh in shaded heatmap; do
    log "render $s 1920x1080 $sh"
    t0=$(date +%s.%N)
    j=$("$bin" render "$scenes/$s.json" -o "$tmp/${s}_$sh.png" --shading $sh --json --quiet | tail -n 1)
    t1=$(date +%s.%N)
    printf "| %s | %s | %.2f s | %.0f ms | %.0f ms |\n" "$s" "$sh" "$(calc '%.3f' "$t1 - $t0")" \
      "$(field "$j" prune_ms)" "$(field "$j" trace_ms)"
    if [ -n "${KEEP_IMAGES:-}" ]; then cp "$tmp/${s}_$sh.png" "$KEEP_IMAGES/"; fi
  done
done

# The Vulkan backend (bench/gpu.sh).
"$(dirname "$0")/gpu.sh" "$build"
