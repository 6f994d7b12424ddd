#!/usr/bin/env bash
# Runs every Neptunus test on a fresh machine: installs what the tests need,
# then checks formatting and lints, the API docs and the user guide, then
# runs the whole test suite.
# This is the README's test command; .ci/run calls exactly this.
set -euo pipefail
cd "$(dirname "$0")/.."

# A clean checkout builds everything once: incremental compilation's caches
# would only fill the disk (about 14 GB of the debug build's 22).
export CARGO_INCREMENTAL="${CARGO_INCREMENTAL:-0}"

# Each stage's header says how long the run has taken so far.
stage() { printf '== %s  [%d min %02d s]\n' "$1" $((SECONDS / 60)) $((SECONDS % 60)); }

stage "toolchain"
cargo --version
rustc --version

as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }

stage "test tools (every package the stages below use, installed here once: two of them run side by side)"
apt_packages=(
    # The camera tests run a real ffmpeg (tests/camera.rs).
    ffmpeg
    # The RTP video tests receive with QGroundControl's own GStreamer
    # pipeline (tests/video_rtp.rs): udpsrc, rtph264depay (good), h264parse
    # (bad), avdec_h264 (libav).
    gstreamer1.0-tools gstreamer1.0-plugins-good gstreamer1.0-plugins-bad gstreamer1.0-libav
    # The clock test runs the vehicle under libfaketime (tests/clock.rs).
    faketime
    # The genuine OpenROV firmware in the loop (feature hil,
    # tests/genuine_*.rs): avr-gcc and the Arduino AVR core build the
    # firmware; simavr (built from the simavr-ffi crate's sources) needs
    # libclang for its bindings, libelf and zstd to load ELF files.
    gcc-avr avr-libc arduino-core-avr libclang-dev libelf-dev libzstd-dev pkg-config
    # The step-response plots (neptunus sim-report) label axes with a system font.
    fonts-dejavu-core
    # libFuzzer (built by libfuzzer-sys) needs a C++ compiler.
    g++
    # The interoperability tests' venv; MAVProxy pulls in opencv-python,
    # which needs libGL and glib at import time.
    python3-venv libgl1 libglib2.0-0
    # Debian's Chromium, never a browser a tool downloads; the many-viewers
    # recipe (tests/browser/janus.test.js) runs Debian's Janus with a
    # configuration of its own (the package's service is not used).
    chromium janus
    # The package checks (tests/package.sh, tests/armhf.sh).
    dpkg systemd file
)
apt_missing=()
for p in "${apt_packages[@]}"; do
    dpkg -s "$p" >/dev/null 2>&1 || apt_missing+=("$p")
done
# Node.js and npm (the browser tests' runner) by command: a machine may have
# them from NodeSource's nodejs, whose npm is no package of its own.
command -v npm >/dev/null 2>&1 || apt_missing+=(nodejs npm)
if [ "${#apt_missing[@]}" -gt 0 ]; then
    as_root apt-get update -q
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -q "${apt_missing[@]}"
fi
# The BeagleBone's toolchain (Debian's Rust with the standard library's
# sources, the cross gcc) as the guide's build script installs it; its
# cargo-deb is built in the background below.
bash debian/build-armhf.sh --packages-only
ffmpeg -hide_banner -version | sed -n 1p
gst-launch-1.0 --version | sed -n 1p
avr-gcc --version | sed -n 1p
# The firmware snapshots the HIL tests build: ../shared/openrov-firmware
# beside the repository unless OPENROV_FIRMWARE_DIR says otherwise.
firmware_dir="${OPENROV_FIRMWARE_DIR:-$PWD/../shared/openrov-firmware}"
if [ ! -f "$firmware_dir/30.0.2/OpenROV/OpenROV.ino" ] || [ ! -f "$firmware_dir/2014-12/OpenROV/OpenROV.ino" ]; then
    echo "the genuine OpenROV firmware is not at $firmware_dir (30.0.2/ and 2014-12/) — set OPENROV_FIRMWARE_DIR; the guide's docs/guide/src/hil.md says how to get it" >&2
    exit 1
fi
export OPENROV_FIRMWARE_DIR="$firmware_dir"

# The page's plotting library, from web/package-lock.json, once: every
# build below embeds it (build.rs), and two of them run side by side.
if [ ! -f web/node_modules/uplot/dist/uPlot.esm.js ]; then
    (cd web && npm ci --no-audit --no-fund --ignore-scripts)
fi

stage "builds that no test needs yet, started in the background at the lowest priority"
# In order: the fuzz targets' instrumented build (fuzz/run.sh, its own
# target/), the user guide's mdBook, the BeagleBone's armhf build
# (tests/armhf.sh build: Debian's Rust, the standard library rebuilt, the
# cross linker, cargo-deb) and this machine's package (cargo deb, the
# `package-check` profile: built as the development build is). At nice 19
# they take what the lints, the tests' build and the real-time tests below
# leave idle; the stages that need them wait for them, and their checks
# run at the end on what they built. Each writes target/bg-NAME.log and
# target/bg-NAME.rc (its exit status).
mdbook_version=0.4.52
rm -f target/bg-*.rc
mkdir -p target
bg() {
    local name=$1 rc=0
    shift
    "$@" >"target/bg-$name.log" 2>&1 || rc=$?
    echo "$rc" >"target/bg-$name.rc"
}
install_mdbook() {
    # Debian has no mdbook package: cargo installs the pinned version once.
    # Only the search feature: the guide is built, never served or watched.
    if [ "$(mdbook --version 2>/dev/null)" != "mdbook v$mdbook_version" ]; then
        cargo install mdbook --locked --version "$mdbook_version" --no-default-features --features search
    fi
}
# Its own process group (job control for this one job), so that a run
# that stops early stops it too.
set -m
(
    renice -n 19 -p "$BASHPID" >/dev/null
    bg fuzz-build env FUZZ_BUILD_ONLY=1 bash fuzz/run.sh
    bg mdbook install_mdbook
    bg armhf bash tests/armhf.sh build
    bg package bash -c 'bash debian/build-armhf.sh --toolchain-only && cargo deb --locked --profile package-check'
) &
background=$!
set +m
trap 'kill -- -"$background" 2>/dev/null || true' EXIT
# Waits until the background job NAME has ended; its exit status.
bg_wait() {
    while [ ! -f "target/bg-$1.rc" ] && kill -0 "$background" 2>/dev/null; do sleep 5; done
    local rc
    rc=$(cat "target/bg-$1.rc" 2>/dev/null || echo 1)
    echo "-- background $1: exit $rc"
    if [ "$rc" != 0 ]; then tail -n 40 "target/bg-$1.log" || true; fi
    return "$rc"
}

stage "formatting and lints"
cargo fmt --all -- --check
cargo clippy --all-targets --locked --features hil -- -D warnings
# The vehicle as packaged (without the simulator of the genuine firmware):
# the library and the program; the tests are the same code as above.
cargo clippy --lib --bins --locked -- -D warnings
# The API docs build without a warning (broken links included).
RUSTDOCFLAGS="-D warnings" cargo doc --no-deps --locked --features hil

stage "tests"
status=0
cargo test --all-targets --locked --features hil --no-fail-fast 2>&1 | tee target/test-output.txt || status=1

stage "fuzzing (every target of fuzz/Cargo.toml, from its seeds, for a bounded time)"
# Its own build in fuzz/target (made in the background: waited for here,
# and made again if it failed); FUZZ_SECONDS per target, two at a time. A
# crash fails the run with the input's path and how to run it again.
bg_wait fuzz-build || true
FUZZ_SECONDS="${FUZZ_SECONDS:-20}" bash fuzz/run.sh || status=1

stage "interoperability tests (real ground-station clients against the binary)"
# A venv in target/ with the pinned clients; reinstalled when the pins change.
venv=target/interop-venv
reqs=tests/interop/requirements.txt
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
fi
if ! cmp -s "$reqs" "$venv/requirements.installed"; then
    "$venv/bin/python" -m pip install -q --disable-pip-version-check -r "$reqs"
    cp "$reqs" "$venv/requirements.installed"
fi
# The vehicle the cargo tests ran (target/debug/neptunus, with the genuine
# firmware's simulator, feature hil, which changes nothing else it does).
# `cargo build` would build it again: without the dev-dependencies, their
# features drop out of the shared crates, and every one of those is
# compiled anew. The packages' builds, without hil, are run by
# tests/package.sh and tests/armhf.sh.
[ -x target/debug/neptunus ] || cargo build --locked --features hil
test -x target/debug/neptunus
rm -f target/interop-junit.xml
NEPTUNUS_BIN="$PWD/target/debug/neptunus" "$venv/bin/python" -m pytest tests/interop -q \
    -p no:cacheprovider --timeout 300 --junitxml target/interop-junit.xml || status=1

stage "browser tests (Debian's Chromium, driven by playwright-core)"
dpkg-query -W -f 'janus ${Version}\n' janus
(cd tests/browser && npm ci --no-audit --no-fund --ignore-scripts) || status=1
rm -f target/browser-junit.xml
(cd tests/browser && NEPTUNUS_BIN="$PWD/../../target/debug/neptunus" node --test --test-concurrency=1 \
    --test-reporter=spec --test-reporter-destination=stdout \
    --test-reporter=junit --test-reporter-destination=../../target/browser-junit.xml \
    ./*.test.js) || status=1

stage "interoperability tests with the genuine firmware in the loop (neptunus --hil)"
# The same clients against `--hil`: QGroundControl's connect sequence,
# pymavlink's everyday calls, depth hold and the mavlink2rest client
# (Cockpit's API), with the 30.0.2 firmware in simavr reading the
# simulator's sensors and driving its thrusters. Then the pilot's browser
# tests (tests/browser/pilot.test.js: arming, driving, the HUD's telemetry,
# depth hold, failsafes, a hung and a restarted vehicle) against it.
rm -f target/interop-hil-junit.xml target/browser-hil-junit.xml
if [ -x target/debug/neptunus ] \
    && hil_elf=$(target/debug/neptunus genuine-board --build-only --data-dir target/hil-data "$firmware_dir/30.0.2" | cut -f1) \
    && [ -f "$hil_elf" ]; then
    hil_elf=$(realpath "$hil_elf")
    NEPTUNUS_HIL_FIRMWARE="$hil_elf" NEPTUNUS_BIN="$PWD/target/debug/neptunus" "$venv/bin/python" -m pytest \
        tests/interop/test_qgc_connect.py tests/interop/test_pymavlink.py tests/interop/test_depth_hold.py \
        tests/interop/test_mavlink2rest.py \
        -q -p no:cacheprovider --timeout 300 --junitxml target/interop-hil-junit.xml || status=1
    (cd tests/browser && NEPTUNUS_HIL_FIRMWARE="$hil_elf" NEPTUNUS_BIN="$PWD/../../target/debug/neptunus" \
        node --test --test-concurrency=1 \
        --test-reporter=spec --test-reporter-destination=stdout \
        --test-reporter=junit --test-reporter-destination=../../target/browser-hil-junit.xml \
        pilot.test.js) || status=1
else
    echo "the genuine firmware could not be built for the --hil tests" >&2
    status=1
fi

stage "the user guide (mdBook: docs/guide -> target/guide)"
# --dest-dir is relative to the book's folder. Its links are checked by
# tests/docs_links.rs; a chapter that fails to render fails the run here.
# It counts as one test in the summary line.
gd_pass=0
gd_fail=0
if bg_wait mdbook && mdbook --version && mdbook build docs/guide --dest-dir ../../target/guide; then
    gd_pass=1
else
    gd_fail=1
    status=1
fi

stage "Debian package (built for this machine and checked: tests/package.sh)"
pk_pass=0
pk_fail=0
if bg_wait package && PACKAGE_PROFILE=package-check bash tests/package.sh; then pk_pass=1; else pk_fail=1; status=1; fi

stage "the BeagleBone's vehicle (armhf: built as the guide says, packaged, run under qemu-arm: tests/armhf.sh)"
# Its build, its package's checks, --sim and the genuine firmware under
# qemu-arm -cpu cortex-a8; it counts as one test here and prints its own.
ah_pass=0
ah_fail=0
if bg_wait armhf && bash tests/armhf.sh check; then ah_pass=1; else ah_fail=1; status=1; fi
wait "$background" || true

# Summarise as one plain line for CI: cargo prints one result line per test
# binary; pytest's and node's counts come from their JUnit XML.
junit_counts() {
    "$venv/bin/python" - "$1" <<'PY' || echo "0 1 0"
import sys, xml.etree.ElementTree as ET
try:
    root = ET.parse(sys.argv[1]).getroot()
except (OSError, ET.ParseError):
    print(0, 1, 0)  # the runner did not even produce a report: count it as a failure
    raise SystemExit
cases = list(root.iter("testcase"))
f = sum(1 for c in cases if c.find("failure") is not None or c.find("error") is not None)
k = sum(1 for c in cases if c.find("skipped") is not None)
print(len(cases) - f - k, f, k)
PY
}
read -r py_pass py_fail py_skip < <(junit_counts target/interop-junit.xml)
read -r hil_pass hil_fail hil_skip < <(junit_counts target/interop-hil-junit.xml)
py_pass=$((py_pass + hil_pass)); py_fail=$((py_fail + hil_fail)); py_skip=$((py_skip + hil_skip))
# Each fuzz target counts as one test (fuzz/run.sh's summary).
fz_pass=$(grep -c ' ok$' fuzz/target/fuzz-logs/summary.txt 2>/dev/null || true)
fz_fail=$(grep -c ' failed$' fuzz/target/fuzz-logs/summary.txt 2>/dev/null || true)
read -r br_pass br_fail br_skip < <(junit_counts target/browser-junit.xml)
read -r brh_pass brh_fail brh_skip < <(junit_counts target/browser-hil-junit.xml)
br_pass=$((br_pass + brh_pass)); br_fail=$((br_fail + brh_fail)); br_skip=$((br_skip + brh_skip))
# What failed, and why, at the end where CI's excerpt of the log shows it:
# a cargo test's panic lines, a pytest or node test's failure message, each
# cut to its first lines.
failure_details() {
    "$venv/bin/python" - "$@" <<'PY' || true
import re, sys, xml.etree.ElementTree as ET
out, shown = [], 0
def add(name, text):
    global shown
    shown += 1
    if shown > 8:
        return
    lines = [l for l in text.splitlines() if l.strip()][:12]
    out.append(f"-- {name}")
    out.extend("   " + l[:300] for l in lines)
try:
    cargo = open(sys.argv[1], encoding="utf-8", errors="replace").read()
except OSError:
    cargo = ""
for m in re.finditer(r"^---- (\S+) stdout ----\n(.*?)(?=^---- |^failures:|\Z)", cargo, re.M | re.S):
    add(m.group(1), m.group(2))
for path in sys.argv[2:]:
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError):
        continue
    for case in root.iter("testcase"):
        bad = case.find("failure") if case.find("failure") is not None else case.find("error")
        if bad is not None:
            add(case.get("name", "?"), (bad.get("message") or "") + "\n" + (bad.text or ""))
if shown:
    print(f"== what failed ({shown}; the first lines of each{', the first 8' if shown > 8 else ''})")
    print("\n".join(out))
PY
}
failure_details target/test-output.txt target/interop-junit.xml target/interop-hil-junit.xml \
    target/browser-junit.xml target/browser-hil-junit.xml target/armhf-junit.xml
cat fuzz/target/fuzz-logs/failures.txt 2>/dev/null || true
awk -v pp="$((py_pass + br_pass + pk_pass + ah_pass + gd_pass + ${fz_pass:-0}))" -v pf="$((py_fail + br_fail + pk_fail + ah_fail + gd_fail + ${fz_fail:-0}))" -v ps="$((py_skip + br_skip))" \
    '/^test result:/ { p += $4; f += $6; i += $8 } END { printf "tests: %d passed, %d failed, %d skipped\n", p + pp, f + pf, i + ps }' \
    target/test-output.txt
exit "$status"
