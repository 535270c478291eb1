#!/usr/bin/env bash
# Runs each libFuzzer target for FUZZ_SECONDS (default 600) and prints its executions and
# coverage. Usage: fuzz/run.sh BUILD_DIR [TARGET...] (targets: scene_loader npy_reader
# prune_eval). The working corpus grows in BUILD_DIR/corpus/<target> (seeded from
# fuzz/corpus/<target>, and for the scene loader from the reference scenes, $SDFPRUNE_SCENES or
# ../shared/scenes, where they are: external data, not committed); crashing, leaking, slow or memory-hungry inputs land in
# BUILD_DIR/artifacts/<target>/ — copy them to fuzz/regressions/<target>/ once fixed.
set -uo pipefail
cd "$(dirname "$0")/.."
build=${1:?usage: fuzz/run.sh BUILD_DIR [TARGET...]}
shift
targets=("$@")
[ ${#targets[@]} -eq 0 ] && targets=(scene_loader npy_reader prune_eval)
seconds=${FUZZ_SECONDS:-600}
status=0
summary=()
for t in "${targets[@]}"; do
    mkdir -p "$build/corpus/$t" "$build/artifacts/$t"
    log="$build/fuzz_$t.log"
    echo "fuzz: $t for ${seconds}s (log: $log)"
    seeds=("fuzz/corpus/$t")
    scenes=${SDFPRUNE_SCENES:-../shared/scenes}
    [ "$t" = scene_loader ] && [ -d "$scenes" ] && seeds+=("$scenes")
    # A slow input (over 10 s) or one needing over 2 GiB counts as a finding.
    "$build/fuzz_$t" "$build/corpus/$t" "${seeds[@]}" -max_total_time="$seconds" \
        -timeout=10 -rss_limit_mb=2048 -malloc_limit_mb=2048 -print_final_stats=1 \
        -artifact_prefix="$build/artifacts/$t/" >"$log" 2>&1
    rc=$?
    [ $rc -ne 0 ] && status=1
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
    last=$(grep -E '^#[0-9]+' "$log" | tail -1)
    cov=$(sed -n 's/.* cov: \([0-9]*\).*/\1/p' <<<"$last")
    ft=$(sed -n 's/.* ft: \([0-9]*\).*/\1/p' <<<"$last")
    corp=$(sed -n 's/.* corp: \([^ ]*\).*/\1/p' <<<"$last")
    rate=$(sed -n 's/.* exec\/s: \([0-9]*\).*/\1/p' <<<"$last")
    line="$t: ${execs:-?} execs (${rate:-?} exec/s), cov ${cov:-?}, ft ${ft:-?}, corpus ${corp:-?}"
    [ $rc -ne 0 ] && line+=" — FINDING (exit $rc), see $log and $build/artifacts/$t/"
    summary+=("$line")
    echo "fuzz: $line"
done
echo "fuzz summary:"
printf '  %s\n' "${summary[@]}"
exit $status
