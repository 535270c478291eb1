#!/usr/bin/env bash
# bench/gpu_steps.sh LABEL=COMMAND [LABEL=COMMAND ...] — the Vulkan pruning's time step by step,
# for comparing builds or settings on one device within one session (BENCHMARKS.md, stop 27).
# Each COMMAND is an sdfprune binary, with settings before it if wanted, for example
#   bash bench/gpu_steps.sh old=/tmp/sdfprune.old new=build/sdfprune \
#     b8="env SDFPRUNE_VULKAN_REFINE_BATCH=8 build/sdfprune"
# Per scene the variants run one after another (`stats --backend vulkan --json --repeat
# REPEAT`, the last run kept), after one untimed warm-up pruning: a fresh machine's GPU ran its
# first scene 3–4 times slower. One line per scene and variant: prune_ms, near-field cells,
# average active primitives (equal across variants, or the variants disagree), the first call's
# wall time, buffer time, peak memory, the device memory it allocated (a first call
# allocates its buffers, but for what the device's reserve holds) and its submissions' time
# (the host's wait for them, the GPU's time in it), the device's making and its
# reserve (its size and its thread's time: the first call did not wait for it, so where it
# allocated much, the reserve came too late) and each step's
# GPU time (L level, o octants, c cells, x refinement, W wide, W2-W8 wide with each job split
# over that many workgroups, R after it: long runs staged in shared memory, from stop 50 on;
# [lane pass's part, <its longest
# tape from stop 48 on]; {the team
# steps' longest walk of a workgroup, in tape entries, measured on the device: builds from
# stop 46 on; from stop 47 on every step's, wide and refinement too, and /the walks of all the
# step's workgroups summed}): a step whose time follows its longest walk waits on its critical
# path, one whose time follows the sum is bound by the device's throughput.
# SDFPRUNE_GPU_SCENES names the scenes (default: molecule, trees and five generated kinds);
# molecule and trees are read from SDFPRUNE_SCENES (default ../shared/scenes), the others
# generated. GRID sets `--grid` (default stats' 256; a small one checks the script on lavapipe).
# ROUNDS=N runs the whole sweep N times (labels LABEL#1 ... LABEL#N): a fresh machine has slowed
# down single runs 2-4x in every step (stops 29, 30 and 35), which a second round shows up.
# SAVE=DIR also keeps each run's whole JSON (every step's shape: dispatches, workgroups, lanes,
# longest walk) as DIR/SCENE.LABEL.json.
set -euo pipefail
[ -n "${SAVE:-}" ] && mkdir -p "$SAVE"
[ $# -ge 1 ] || { echo "usage: bench/gpu_steps.sh LABEL=COMMAND [LABEL=COMMAND ...]" >&2; exit 2; }
here=$(cd "$(dirname "$0")" && pwd)
scenes=${SDFPRUNE_SCENES:-$here/../../shared/scenes}
repeat=${REPEAT:-3}
rounds=${ROUNDS:-1}
grid=()
[ -n "${GRID:-}" ] && grid=(--grid "$GRID")
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

labels=() commands=()
for v in "$@"; do
  case $v in
    *=*) labels+=("${v%%=*}"); commands+=("${v#*=}") ;;
    *) echo "gpu_steps: '$v' is not LABEL=COMMAND" >&2; exit 2 ;;
  esac
done
first=${commands[0]}
for k in ${SDFPRUNE_GPU_SCENES:-molecule trees character gameboy crowd monument fluid}; do
  case $k in
    molecule | trees) cp "$scenes/$k.json" "$tmp/$k.json" ;;
    *) $first generate "$k" -o "$tmp/$k.json" >/dev/null ;;
  esac
done

# One stats line: the last JSON object of the output, in a line.
show() {  # show SCENE LABEL < stats output
  python3 -c '
import json, os, sys
scene, label = sys.argv[1], sys.argv[2]
d = None
for line in sys.stdin:
    if line.startswith("{"):
        d = json.loads(line)
    elif line.strip():
        print(scene, label, "says:", line.strip()[:200])
if d is not None and os.environ.get("SAVE"):
    with open(os.path.join(os.environ["SAVE"], "%s.%s.json" % (scene, label.replace("#", "_"))), "w") as f:
        json.dump(d, f)
if d is None:
    print(scene, label, "no result")
else:
    def kernel(s):  # W wide, W2..W8 its jobs split over that many workgroups, R its runs staged
        split = s.get("lanes_per_tape", 256) // 256
        runs = "R" if s.get("wide_runs") else ""
        return ("W%d" % split if split > 1 else "W") + runs if s["wide"] else ""
    steps = " ".join("L%d%s%s:%.2f" % (s["level"], "bocx"[s["mode"]], kernel(s), s["gpu_ms"]) +
                     ("[%.2f%s]" % (s["lanes_ms"], "<%d" % s["lane_tape"] if s.get("lane_tape") else "")
                      if s.get("lanes_ms") else "") +
                     ("{%d/%d}" % (s["walked_words"], s["walked_sum_words"])
                      if s.get("walked_sum_words") else
                      "{%d}" % s["walked_words"] if s.get("walked_words") else "")
                     for s in d["gpu_steps"])
    first = ""
    if "first_wall_ms" in d:  # the first call of the process: wall time, buffer time, peak
        first = "first %.1f/%.1f ms wall/buffers, peak %.0f MB" % (
            d["first_wall_ms"], d["first_host_buffer_ms"], d["first_prune_peak_bytes"] / 1e6)
        if "first_host_allocated_bytes" in d:  # (builds from stop 42 on)
            first += ", allocated %.0f MB" % (d["first_host_allocated_bytes"] / 1e6)
        if "first_host_submit_ms" in d:  # (stop 43 on): its submissions, waited for, and GPU time
            first += ", submissions %.1f ms (GPU %.1f)" % (d["first_host_submit_ms"],
                                                            d["first_prune_ms"])
        if "device_ms" in d:  # (builds from stop 43 on): making the device, and its reserve
            first += ", device %.1f ms, reserve %.0f MB in %.1f ms" % (
                d["device_ms"], d["device_reserve_bytes"] / 1e6, d["device_reserve_ms"])
    print(scene, label, "%.2f ms" % d["prune_ms"], "near", d["near_field_cells"],
          "active %.5f" % d["active_avg"], first, steps)
' "$1" "$2"
}

$first stats builtin:demo "${grid[@]}" --backend vulkan --json >/dev/null  # the warm-up
for round in $(seq 1 "$rounds"); do
  for f in "$tmp"/*.json; do
    k=$(basename "$f" .json)
    for i in "${!labels[@]}"; do
      label=${labels[$i]}
      [ "$rounds" -gt 1 ] && label="$label#$round"
      ${commands[$i]} stats "$f" "${grid[@]}" --backend vulkan --json --repeat "$repeat" 2>&1 |
        show "$k" "$label"
    done
  done
done
