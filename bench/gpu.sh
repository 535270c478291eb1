#!/usr/bin/env bash
# bench/gpu.sh BUILD_DIR [RESULTS.json] — the Vulkan backend's part of BENCHMARKS.md (markdown on
# stdout): the paper's Table 1 columns (T_p, T_s, T_d, M_p) for molecule, trees and the 14
# generated kinds on the Vulkan device, beside the paper's RTX 4060 figures and the same
# machine's CPU backend (all its cores). Writes one JSON object per scene and device to
# RESULTS.json (default BUILD_DIR/gpu-results.json): device, scene, prune_ms, prune_lipschitz_ms,
# wall_ms, trace_ms, prune_trace_ms, discretize_ms, prune_peak_bytes, cpu_prune_ms, cpu_threads,
# stats_equal, and the first call's host side: device_ms (making the device), device_reserve_bytes
# and host_allocated_bytes (README: the device's reserve). bench/gpu-results.json holds a real GPU's, made with
# `bash bench/gpu.sh build bench/gpu-results.json`. A note instead when there is no Vulkan
# device. Called by bench/targets.sh. SDFPRUNE_GPU_SCENES names the scenes (space-separated);
# on lavapipe, which runs on the CPU, the default is molecule, trees and fluid.
# SDFPRUNE_GPU_FLUID_COUNTS (e.g. "100000 1000000") adds generated fluids of that many spheres
# (scenes fluid-N: pruning only, GPU and CPU, each within SDFPRUNE_GPU_TIMEOUT seconds, default
# 300). Each object also holds prune_steps: the GPU pruning's steps (level, mode, wide, jobs,
# lanes, lanes_ms, long_jobs, longest_walk_words, gpu_ms), where its time goes.
set -euo pipefail
build=${1:-build}
here=$(cd "$(dirname "$0")" && pwd)
results=${2:-$build/gpu-results.json}
bin="$build/sdfprune"
scenes=${SDFPRUNE_SCENES:-$here/../../shared/scenes}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
log() { echo "bench: $*" >&2; }

# The device, probed once: its stats line, or nothing where there is none.
probe=$("$bin" stats builtin:sphere --grid 8 --backend vulkan --json 2>/dev/null | tail -n 1) || probe=""
if [ -z "$probe" ]; then
  echo
  echo "## Vulkan backend"
  echo
  echo "No Vulkan device on this machine (\`--backend vulkan\` exits 2): not measured."
  exit 0
fi

kinds="molecule trees character raccoon console gameboy car train-station camera car-chase city
  crowd monument fluid"
if grep -q llvmpipe <<<"$probe"; then
  kinds="molecule trees fluid"
fi
kinds=${SDFPRUNE_GPU_SCENES:-$kinds}
threads=$(nproc)
: >"$tmp/runs.jsonl"
# One scene: each command's JSON line (or its error) into runs.jsonl, tagged with what ran.
run() {  # run NAME WHAT COMMAND...
  local name=$1 what=$2
  shift 2
  local out
  if out=$("$@" 2>"$tmp/err" | tail -n 1) && [ -n "$out" ]; then
    printf '{"name":"%s","what":"%s","result":%s}\n' "$name" "$what" "$out" >>"$tmp/runs.jsonl"
  else
    log "$name $what failed: $(head -c 300 "$tmp/err")"
    printf '{"name":"%s","what":"%s","error":%s}\n' "$name" "$what" \
      "$(head -c 300 "$tmp/err" | python3 -c 'import json,sys; print(json.dumps(sys.stdin.read()))')" \
      >>"$tmp/runs.jsonl"
  fi
}
for k in $kinds; do
  case $k in
    molecule | trees) f="$scenes/$k.json" ;;
    *) f="$tmp/$k.json"; "$bin" generate "$k" -o "$f" >/dev/null || continue ;;
  esac
  [ -f "$f" ] || { log "$k: no scene file $f"; continue; }
  log "vulkan $k"
  run "$k" gpu "$bin" stats "$f" --backend vulkan --json
  run "$k" gpu_lipschitz "$bin" stats "$f" --backend vulkan --lipschitz-bounds --json
  run "$k" cpu "$bin" stats "$f" --threads "$threads" --json
  run "$k" trace "$bin" render "$f" -o "$tmp/$k.png" --width 1920 --height 1080 \
    --backend vulkan --json --quiet
  run "$k" discretize "$bin" discretize "$f" -o "$tmp/$k.npy" --res 256 --backend vulkan \
    --json --quiet
done

for n in ${SDFPRUNE_GPU_FLUID_COUNTS:-}; do
  f="$tmp/fluid-$n.json"
  "$bin" generate fluid --count "$n" -o "$f" >/dev/null || { log "fluid-$n: generate failed"; continue; }
  log "vulkan fluid-$n"
  run "fluid-$n" gpu timeout "${SDFPRUNE_GPU_TIMEOUT:-300}" "$bin" stats "$f" --backend vulkan --json
  run "fluid-$n" cpu timeout "${SDFPRUNE_GPU_TIMEOUT:-300}" "$bin" stats "$f" --threads "$threads" --json
  rm -f "$f"
done

python3 - "$tmp/runs.jsonl" "$results" "$here/paper/table1.csv" "$threads" <<'EOF'
import csv, json, sys
runs_path, results_path, paper_path, threads = sys.argv[1:5]
runs = {}
for line in open(runs_path):
    r = json.loads(line)
    runs.setdefault(r["name"], {})[r["what"]] = r.get("result")
paper = {}
for row in csv.DictReader(l for l in open(paper_path) if not l.startswith("#")):
    paper[row["scene"].lower().replace(" ", "-")] = row
same_keys = ["near_field_cells", "active_avg", "active_max", "tape_avg", "tape_max"]
objects, device = [], None
for name, r in runs.items():
    g, c, t, d, gl = (r.get(k) for k in ("gpu", "cpu", "trace", "discretize", "gpu_lipschitz"))
    device = device or (g or {}).get("device")
    same = None
    if g and c:  # within a relative 1e-4 (real GPUs round sqrt and division differently)
        same = all(abs(g[k] - c[k]) <= 1e-4 * max(abs(c[k]), 1) for k in same_keys)
    objects.append({
        "device": (g or t or d or {}).get("device"), "scene": name,
        "prune_ms": g and g["prune_ms"], "prune_lipschitz_ms": gl and gl["prune_ms"],
        "wall_ms": g and g.get("wall_ms"),
        # (builds from stop 43 on) making the device, and its reserve
        "device_ms": g and g.get("device_ms"), "device_reserve_bytes": g and g.get("device_reserve_bytes"),
        "host_allocated_bytes": g and g.get("host_allocated_bytes"),
        "trace_ms": t and t["trace_ms"], "prune_trace_ms": t and t["prune_ms"] + t["trace_ms"],
        "discretize_ms": d and d["eval_ms"], "prune_peak_bytes": g and g["prune_peak_bytes"],
        "cpu_prune_ms": c and c["prune_ms"], "cpu_threads": int(threads), "stats_equal": same,
        "prune_steps": g and [{k: st.get(k) for k in ("level", "mode", "wide", "jobs", "lanes", "lanes_ms", "lane_tape", "long_jobs",
                                                      "longest_walk_words", "gpu_ms")}
                              for st in g.get("gpu_steps", [])]})
with open(results_path, "w") as f:
    json.dump(objects, f, indent=1)
    f.write("\n")
fmt = lambda v, unit=" ms": "–" if v is None else f"{v:.2f}{unit}"
print(f"\n## Vulkan backend (`--backend vulkan`) on {device}\n")
print("GPU timestamps (`prune_ms`, `trace_ms`, `eval_ms`); `wall_ms` is the host's whole pruning call;")
print(f"CPU: the same machine's CPU backend on {threads} threads. T_s is 1920x1080 with shadows; T_d is")
print("discretize 256³. M_p is the backend's device memory while pruning. Statistics: GPU against")
print("CPU (near-field cells, active primitives, tape lengths), equal within 1e-4.\n")
print("| scene | T_p | T_p Lipschitz | wall | T_s | T_p + T_s | T_d | M_p | CPU T_p | CPU / GPU | statistics | paper 4060: T_p / T_s / T_d / M_p |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|")
for o in objects:
    p = paper.get(o["scene"], {})
    ref = " / ".join(p.get(k) or "–" for k in ("ours_Tp", "ours_Ts", "ours_Td")) + \
        (f" ms / {p['ours_Mp']} GB" if p.get("ours_Mp") else "")
    ratio = "–" if not (o["prune_ms"] and o["cpu_prune_ms"]) else f"×{o['cpu_prune_ms'] / o['prune_ms']:.1f}"
    mp = "–" if o["prune_peak_bytes"] is None else f"{o['prune_peak_bytes'] / 1e6:.0f} MB"
    st = {True: "equal", False: "DIFFER", None: "–"}[o["stats_equal"]]
    print(f"| {o['scene']} | {fmt(o['prune_ms'])} | {fmt(o['prune_lipschitz_ms'])} | {fmt(o['wall_ms'])} | "
          f"{fmt(o['trace_ms'])} | {fmt(o['prune_trace_ms'])} | {fmt(o['discretize_ms'])} | {mp} | "
          f"{fmt(o['cpu_prune_ms'])} | {ratio} | {st} | {ref or '–'} |")
EOF
