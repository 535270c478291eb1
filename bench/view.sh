#!/usr/bin/env bash
# view.sh BUILD [SCENE] — the viewer's targets, measured through its HTTP API as the page uses it
# (curl on 127.0.0.1; CPU backend): frames per second while orbiting at the moving resolution
# (480x270, requests one after another along an orbit, PNG encoding and transfer included), the
# full 960x540 frame after the camera rests, and the time from an edit (one atom moved) to the
# refreshed 480x270 frame. Prints one line per figure and a JSON line at the end.
set -euo pipefail
build="${1:?usage: view.sh BUILD [SCENE]}"
scene="${2:-$(dirname "$0")/../../shared/scenes/molecule.json}"
[ -f "$scene" ] || { echo "view.sh: $scene not found" >&2; exit 2; }
dir=$(mktemp -d)
trap 'kill $pid 2>/dev/null || true; rm -rf "$dir"' EXIT
cp "$scene" "$dir/scene.json"
"$build/sdfprune" view "$dir/scene.json" --port 0 > "$dir/out.txt" &
pid=$!
for _ in $(seq 100); do grep -q 'serving' "$dir/out.txt" 2>/dev/null && break; sleep 0.1; done
url=$(grep -o 'http://127.0.0.1:[0-9]*' "$dir/out.txt")
t() { curl -s -o /dev/null -w '%{time_total}' "$@"; }
# The first frame prunes the grid (not counted).
prune_s=$(t "$url/api/frame?w=480&h=270")
frames=30
# One curl for the whole orbit: one kept-alive connection, as the page's fetches use.
urls=()
for i in $(seq $frames); do urls+=("$url/api/frame?w=480&h=270&yaw=$((30 + 2 * i))"); done
start=$(date +%s.%N)
curl -s $(printf -- '-o /dev/null %s ' "${urls[@]}")
orbit_s=$(awk "BEGIN{print $(date +%s.%N) - $start}")
fps=$(awk "BEGIN{print $frames / $orbit_s}")
full_s=$(t "$url/api/frame?w=960&h=540&yaw=90")
# Edits: one atom moved in small steps, each followed by the frame the page asks for. The first
# two updates copy the grid (no spare grid yet); the median of the rest is reported.
edits=()
for i in $(seq 9); do
  e=$(t -X POST -d "{\"primitive\":500,\"set\":{\"translate.x\":0.0$i}}" "$url/api/edit")
  f=$(t "$url/api/frame?w=480&h=270&yaw=90&highlight=500")
  edits+=("$(awk "BEGIN{print ($e + $f) * 1000}")")
done
edit_ms=$(printf '%s\n' "${edits[@]:2}" | sort -n | sed -n 4p)
printf 'first frame (prunes the 256^3 grid): %.0f ms\n' "$(awk "BEGIN{print $prune_s * 1000}")"
printf 'orbit at 480x270: %.1f frames per second (%d frames in %.2f s)\n' "$fps" $frames "$orbit_s"
printf 'full 960x540 frame at rest: %.0f ms\n' "$(awk "BEGIN{print $full_s * 1000}")"
printf 'edit to refreshed 480x270 frame: %.0f ms (median of 7)\n' "$edit_ms"
printf '{"scene":"%s","orbit_fps":%.2f,"full_frame_ms":%.1f,"edit_to_frame_ms":%.1f}\n' \
  "$(basename "$scene")" "$fps" "$(awk "BEGIN{print $full_s * 1000}")" "$edit_ms"
