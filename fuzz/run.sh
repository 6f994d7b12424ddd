#!/usr/bin/env bash
# Builds the fuzz targets (every [[bin]] of fuzz/Cargo.toml) for libFuzzer
# on the stable toolchain and runs each for a bounded time from its seeds
# (fuzz/seeds/TARGET/), FUZZ_JOBS at a time. Fails when a target finds a
# crash, printing the input's path and how to run it again.
#
#   bash fuzz/run.sh                            # every target
#   FUZZ_SECONDS=600 bash fuzz/run.sh rtp_depay # one target, ten minutes
#   FUZZ_BUILD_ONLY=1 bash fuzz/run.sh          # only the build (the test
#                                               # command makes it early)
#
# FUZZ_SECONDS: seconds per target (default 20). FUZZ_JOBS: targets at
# once (default 2). Everything it makes stays in fuzz/target (the build,
# the corpus each run grows, the logs) and fuzz/artifacts (crashes).
set -euo pipefail
cd "$(dirname "$0")"

seconds=${FUZZ_SECONDS:-20}
jobs=${FUZZ_JOBS:-2}
triple=$(rustc -vV | sed -n 's/^host: //p')
# Its own target/ whatever the environment says: the instrumented build
# must not mix with the main one.
export CARGO_TARGET_DIR="$PWD/target"
# What cargo-fuzz passes (coverage counters, comparisons traced, checks
# on), without its nightly-only sanitizer flags, and without its `fuzzing`
# cfg: no crate may build differently (skip a checksum) for the fuzzer.
export RUSTFLAGS="-Cpasses=sancov-module -Cllvm-args=-sanitizer-coverage-level=4 \
-Cllvm-args=-sanitizer-coverage-inline-8bit-counters -Cllvm-args=-sanitizer-coverage-pc-table \
-Cllvm-args=-sanitizer-coverage-trace-compares -Cdebug-assertions -Coverflow-checks"

# The targets, as cargo reads them from Cargo.toml.
all=$(cargo metadata --no-deps --locked --format-version 1 | python3 -c '
import json, sys
for p in json.load(sys.stdin)["packages"]:
    for t in p["targets"]:
        if "bin" in t["kind"]:
            print(t["name"])')
targets=${*:-$all}
for t in $targets; do
    grep -qx "$t" <<<"$all" || { echo "no fuzz target $t (the [[bin]]s of fuzz/Cargo.toml: $(echo $all))" >&2; exit 2; }
done

bin_dir="$CARGO_TARGET_DIR/$triple/release"
logs="$CARGO_TARGET_DIR/fuzz-logs"
# summary.txt: one line per target, "TARGET ok" or "TARGET failed" (the
# test command counts them); failures.txt: what to do about each failure.
mkdir -p "$logs"
rm -f "$logs/summary.txt" "$logs/failures.txt"

echo "== fuzz: building $(wc -w <<<"$targets") targets"
build_start=$(date +%s)
# shellcheck disable=SC2046 # one --bin per target
if ! cargo build --release --locked --target "$triple" $(printf -- '--bin %s ' $targets); then
    echo "fuzz-build failed" >"$logs/summary.txt"
    echo "-- the fuzz targets did not build: bash fuzz/run.sh shows why" >"$logs/failures.txt"
    exit 1
fi
echo "build: $(( $(date +%s) - build_start )) s"
if [ -n "${FUZZ_BUILD_ONLY:-}" ]; then
    exit 0
fi

run_one() {
    local t=$1 corpus="$CARGO_TARGET_DIR/corpus/$1" seeds="seeds/$1" rc=0
    mkdir -p "$corpus" "artifacts/$t"
    [ -d "$seeds" ] || { mkdir -p "$seeds.none"; seeds="$seeds.none"; }
    # New inputs go to the first folder (the run's corpus); the seeds are
    # only read. A hang of 30 s on one input counts as a crash.
    "$bin_dir/$t" "$corpus" "$seeds" -max_total_time="$seconds" -timeout=30 \
        -artifact_prefix="artifacts/$t/" -print_final_stats=1 >"$logs/$t.log" 2>&1 || rc=$?
    echo "$rc" >"$logs/$t.rc"
}

echo "== fuzz: $seconds s per target, $jobs at a time"
running=0
for t in $targets; do
    rm -f "$logs/$t.rc"
    run_one "$t" &
    running=$((running + 1))
    if [ "$running" -ge "$jobs" ]; then
        wait -n || true
        running=$((running - 1))
    fi
done
wait || true

status=0
printf '%-20s %12s %10s %8s  %s\n' target executions "per second" corpus result
for t in $targets; do
    log="$logs/$t.log"
    rc=$(cat "$logs/$t.rc" 2>/dev/null || echo 1)
    runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
    rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
    units=$(find "$CARGO_TARGET_DIR/corpus/$t" -type f | wc -l)
    if [ "$rc" = 0 ]; then
        printf '%-20s %12s %10s %8s  %s\n' "$t" "${runs:-?}" "${rate:-?}" "$units" "no crash"
        echo "$t ok" >>"$logs/summary.txt"
    else
        status=1
        printf '%-20s %12s %10s %8s  %s\n' "$t" "${runs:-?}" "${rate:-?}" "$units" "FAILED (exit $rc)"
        echo "$t failed" >>"$logs/summary.txt"
    fi
done
for t in $targets; do
    rc=$(cat "$logs/$t.rc" 2>/dev/null || echo 1)
    [ "$rc" = 0 ] && continue
    input=$(sed -n 's/.*Test unit written to \(.*\)$/\1/p' "$logs/$t.log" | tail -1)
    echo "== fuzz target $t failed (exit $rc); the end of its log ($logs/$t.log):"
    # The panic's message and the libFuzzer lines after it.
    grep -v '^#[0-9]' "$logs/$t.log" | tail -25
    {
        echo "-- fuzz target $t: $(grep -m1 -A2 'panicked at' "$logs/$t.log" | tr '\n' ' ' | cut -c1-300)"
        if [ -n "$input" ]; then
            echo "   crashing input: fuzz/$input"
            echo "   run it again:   fuzz/target/$triple/release/$t fuzz/$input"
            echo "                   (after a change, bash fuzz/run.sh $t rebuilds first; or"
            echo "                   cargo fuzz run --sanitizer none $t fuzz/$input)"
            echo "   then fix the parser and keep the input as a regression test (docs/guide/src/tests.md, Fuzzing)"
        else
            echo "   no input was written (see $logs/$t.log)"
        fi
    } | tee -a "$logs/failures.txt"
done
exit "$status"
