#!/usr/bin/env bash
# bench/gpu.sh BUILD_DIR — the Vulkan backend's part of BENCHMARKS.md (markdown on stdout): the
# paper's Table 1 columns for the GPU path on molecule, trees and the generated 28k-node fluid,
# with the device's name; a note when there is no Vulkan device. Called by bench/targets.sh.
set -euo pipefail
build=${1:-build}
bin="$build/sdfprune"
scenes=${SDFPRUNE_SCENES:-$(dirname "$0")/../../shared/scenes}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
log() { echo "bench: $*" >&2; }
field() { sed -E "s/.*\"$2\":\"?([^,\"}]*)\"?.*/\1/" <<<"$1"; }
calc() { awk "BEGIN { printf \"$1\n\", $2 }"; }
[ -f "$scenes/molecule.json" ] || { log "reference scenes not found in $scenes"; exit 0; }

if "$bin" stats builtin:sphere --grid 8 --backend vulkan >/dev/null 2>&1; then
  dev=$("$bin" stats builtin:sphere --grid 8 --backend vulkan --json | tail -n 1 |
        sed -E 's/.*"device":"([^"]*)".*/\1/')
  echo
  echo "## Vulkan backend (\`--backend vulkan\`) on $dev"
  echo
  case $dev in
    llvmpipe*)
      echo "This device is Mesa's lavapipe, a Vulkan driver that runs on the CPU above: the figures"
      echo "check that the GPU path works at full size; they do not measure a GPU." ;;
  esac
  echo "GPU timestamps; device memory as allocated by the backend; statistics compared with the"
  echo "CPU backend's at the same settings. Fluid: \`sdfprune generate fluid\` (27,977 nodes, seed 1)."
  echo "T_p + T_s comes from the render command, which prunes again (its own T_p)."
  echo
  echo "| scene | T_p prune | T_s trace 1920x1080 | T_p + T_s | T_d discretize 256³ | M_p device memory | statistics vs CPU | paper RTX 4060: T_p / T_s / T_d / M_p |"
  echo "|---|---|---|---|---|---|---|---|"
  "$bin" generate fluid -o "$tmp/fluid.json" >/dev/null
  for s in molecule trees fluid; do
    case $s in
      molecule) f="$scenes/molecule.json"; paper="8.9 / 6.97 / 1.48 ms / 1.47 GB";;
      trees) f="$scenes/trees.json"; paper="2.73 / 13.01 / 1.24 ms / 0.64 GB";;
      fluid) f="$tmp/fluid.json"; paper="125.54 / 78.52 / 6.99 ms / 5.68 GB";;
    esac
    log "vulkan $s"
    g=$("$bin" stats "$f" --backend vulkan --json 2>"$tmp/err" | tail -n 1) || g=""
    if [ -z "$g" ]; then
      echo "| $s | failed: $(head -c 200 "$tmp/err") | | | | | | $paper |"
      continue
    fi
    c=$("$bin" stats "$f" --json | tail -n 1)
    same="equal"
    for k in near_field_cells active_avg active_std active_max tape_avg tape_max; do
      [ "$(field "$g" $k)" = "$(field "$c" $k)" ] || same="DIFFER ($k)"
    done
    r=$("$bin" render "$f" -o "$tmp/${s}_gpu.png" --backend vulkan --json --quiet 2>"$tmp/err" | tail -n 1) || r=""
    d=$("$bin" discretize "$f" -o "$tmp/${s}_gpu.npy" --res 256 --backend vulkan --json --quiet 2>>"$tmp/err" | tail -n 1) || d=""
    ts="–"; tpts="–"; td="–"
    if [ -n "$r" ]; then
      ts=$(printf "%.1f ms" "$(field "$r" trace_ms)")
      tpts=$(printf "%.1f ms" "$(calc '%.3f' "$(field "$r" prune_ms) + $(field "$r" trace_ms)")")
    fi
    [ -n "$d" ] && td=$(printf "%.1f ms" "$(field "$d" eval_ms)")
    printf "| %s | %.1f ms | %s | %s | %s | %.1f MB | %s | %s |\n" "$s" "$(field "$g" prune_ms)" "$ts" "$tpts" \
      "$td" "$(calc '%.3f' "$(field "$g" prune_peak_bytes) / 1e6")" "$same" "$paper"
    if [ -s "$tmp/err" ]; then log "vulkan $s: $(head -c 300 "$tmp/err")"; fi
  done
else
  echo
  echo "## Vulkan backend"
  echo
  echo "No Vulkan device on this machine (\`--backend vulkan\` exits 2): not measured."
fi
