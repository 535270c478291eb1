#!/usr/bin/env bash
# make run: the main job on the built-in demo scene (no scene file needed): prune it, render it
# on the pruned grid and naively (the full tree at every step), and print the speed-up.
set -euo pipefail
build=${1:-build}
bin="$build/sdfprune"
out=out
mkdir -p "$out"
w=960 h=540

echo "== the scene"
"$bin" info builtin:demo
echo
echo "== pruning it over a 256³ grid"
"$bin" stats builtin:demo
echo
echo "== rendering ${w}x${h}: pruned grid vs the full tree (naive)"
pruned=$("$bin" render builtin:demo -o "$out/demo.png" --width $w --height $h --json | tail -n 1)
"$bin" render builtin:demo -o "$out/demo_heatmap.png" --width $w --height $h --shading heatmap --quiet
naive=$("$bin" render builtin:demo -o "$out/demo_naive.png" --width $w --height $h --method naive --json | tail -n 1)
field() { sed -E "s/.*\"$2\":([-0-9.e+]+).*/\1/" <<<"$1"; }
awk -v p="$(field "$pruned" trace_ms)" -v pm="$(field "$pruned" prune_ms)" \
    -v n="$(field "$naive" trace_ms)" -v pe="$(field "$pruned" evals_avg)" \
    -v ne="$(field "$naive" evals_avg)" 'BEGIN {
  printf "  pruned: prune %.0f ms + trace %.0f ms (%.0f node evaluations per pixel)\n", pm, p, pe
  printf "  naive:  trace %.0f ms (%.0f node evaluations per pixel)\n", n, ne
  printf "  speed-up of tracing: x%.1f (x%.1f including pruning)\n", n / p, n / (p + pm)
}'
echo
echo "wrote $out/demo.png (shaded), $out/demo_heatmap.png (node evaluations per pixel)"
echo "and $out/demo_naive.png (the naive render, for comparison)"
