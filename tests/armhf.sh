#!/usr/bin/env bash
# The BeagleBone's vehicle in the test command: builds the armhf binary and
# package exactly as the guide tells an owner (debian/build-armhf.sh), with
# the page's plotting library from the file this run's development build
# installed and no npm; checks the package (control data says armhf, the
# binary is a 32-bit ARM hard-float ELF, the newest glibc symbol version it
# needs is what docs/guide/src/install.md states); then runs that binary
# under Debian 13's qemu-arm as a Cortex-A8:
# - `--sim` driven by pymavlink (heartbeat, arm, drive), mavlink2rest (REST
#   and Cockpit's WebSocket) and the HMI page over HTTP (tests/interop);
# - against the genuine 30.0.2 firmware in simavr (tests/genuine_firmware.rs,
#   its armhf test): link up, battery, a normal arm, ESC pulses forward and
#   back to neutral, the board's dead-man stop.
# Nothing here skips: a missing binary, qemu or firmware fails the step.
# Prints its own `armhf: N passed, N failed` line.
#
#   bash tests/armhf.sh          the build, then the checks
#   bash tests/armhf.sh build    only the build (the test command runs it in
#                                the background while its other tests run)
#   bash tests/armhf.sh check    only the checks, on the build already made
set -euo pipefail
cd "$(dirname "$0")/.."

as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }
passed=0
failed=0
ok() { passed=$((passed + 1)); echo "armhf: ok: $*"; }
bad() { failed=$((failed + 1)); echo "armhf: FAIL: $*" >&2; }
finish() {
    echo "armhf: $passed passed, $failed failed"
    [ "$failed" = 0 ] && [ "$passed" -gt 0 ]
}

target=armv7-unknown-linux-gnueabihf
bin="target/$target/rov/neptunus"
started=$(date +%s)

phase="${1:-all}"
case "$phase" in
all | build | check) ;;
*)
    echo "usage: bash tests/armhf.sh [build|check]" >&2
    exit 2
    ;;
esac
if [ "$phase" != check ]; then
    echo "== armhf: the package (debian/build-armhf.sh, no npm)"
    uplot="$PWD/web/node_modules/uplot/dist"
    if [ ! -f "$uplot/uPlot.esm.js" ]; then
        # The development build of this run installs it (build.rs, npm ci).
        cargo build --locked
    fi
    if ! NEPTUNUS_UPLOT_DIR="$uplot" NPM=/bin/false bash debian/build-armhf.sh; then
        bad "the armhf build"
        finish
        exit 1
    fi
    echo "armhf: built in $(($(date +%s) - started)) s"
    if [ "$phase" = build ]; then
        exit 0
    fi
fi
if ! command -v file >/dev/null 2>&1; then
    as_root apt-get update -q && as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -q file
fi
if ! deb=$(ls "target/$target/debian/"neptunus_*_armhf.deb 2>/dev/null) || [ ! -x "$bin" ]; then
    bad "no armhf build to check (target/$target/debian/, $bin): bash tests/armhf.sh build"
    finish
    exit 1
fi
echo "$deb: $(stat -c %s "$deb") bytes (the binary: $(stat -c %s "$bin") bytes)"
info=$(dpkg-deb -I "$deb")
if grep -q '^ Architecture: armhf$' <<<"$info"; then ok "control data: Architecture armhf"; else bad "control data does not say armhf:"$'\n'"$info"; fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
dpkg-deb -x "$deb" "$work/root"
packaged="$work/root/usr/bin/neptunus"
cmp -s "$packaged" "$bin" || bad "the packaged binary is not $bin"
# `file` and the ELF header: 32-bit ARM, EABI 5, hard-float (VFP registers).
desc=$(file -b "$packaged")
header=$(arm-linux-gnueabihf-readelf -h -A "$packaged")
echo "file: $desc"
if grep -q 'ELF 32-bit LSB' <<<"$desc" && grep -q ', ARM, EABI5' <<<"$desc" \
    && grep -Eq 'Flags: .*hard-float ABI' <<<"$header" && grep -q 'Tag_ABI_VFP_args: VFP registers' <<<"$header"; then
    ok "an ARM EABI5 hard-float ELF"
else
    bad "not an ARM hard-float ELF: $desc"$'\n'"$(grep -E 'Flags|Tag_ABI_VFP' <<<"$header")"
fi
# The newest glibc symbol version it needs decides the oldest image it runs
# on: the guide says BeagleBoard.org's Debian 12 (bookworm, glibc 2.36)
# based images, not Debian 11's (bullseye, 2.31).
versions=$(arm-linux-gnueabihf-objdump -T "$packaged" | grep -o 'GLIBC_[0-9][0-9.]*' | sort -uV)
newest=$(tail -1 <<<"$versions" | sed 's/GLIBC_//')
echo "glibc symbol versions needed: $(tr '\n' ' ' <<<"$versions")"
if arm-linux-gnueabihf-objdump -p "$packaged" | grep -q GLIBC_ABI_DT_RELR; then
    bad "needs GLIBC_ABI_DT_RELR (packed relocations): the guide's oldest image would be wrong"
elif [ -n "$newest" ] && [ "$(printf '%s\n' "$newest" 2.36 | sort -V | tail -1)" = 2.36 ] \
    && [ "$(printf '%s\n' "$newest" 2.31 | sort -V | tail -1)" = "$newest" ] && [ "$newest" != 2.31 ]; then
    ok "needs glibc $newest: Debian 12 (glibc 2.36) based images, not Debian 11's 2.31"
else
    bad "needs glibc '$newest': docs/guide/src/install.md states 2.32-2.36 (Debian 12 based images)"
fi

echo "== armhf: Debian 13's qemu-user (unpacked, not installed)"
# Debian 12's qemu 7.2 lacks the termios2 ioctl (TCGETS2) the serial port
# crate uses; trixie's 10.0 has it. Its package lists and .deb go to
# target/qemu-trixie (this machine's apt sources stay as they are).
qroot="$PWD/target/qemu-trixie"
qemu="$qroot/root/usr/bin/qemu-arm"
if [ ! -x "$qemu" ]; then
    mkdir -p "$qroot/lists/partial" "$qroot/cache/archives/partial"
    echo "deb [signed-by=/usr/share/keyrings/debian-archive-keyring.gpg] http://deb.debian.org/debian trixie main" \
        >"$qroot/sources.list"
    apt_t=(-o "Dir::Etc::SourceList=$qroot/sources.list" -o Dir::Etc::SourceParts=/dev/null
        -o "Dir::State::Lists=$qroot/lists" -o "Dir::Cache=$qroot/cache")
    as_root apt-get "${apt_t[@]}" update -q
    rm -f "$qroot"/qemu-user_*.deb
    (cd "$qroot" && as_root apt-get "${apt_t[@]}" download qemu-user)
    dpkg-deb -x "$qroot"/qemu-user_*.deb "$qroot/root"
fi
"$qemu" --version | sed -n 1p
qemu_version=$("$qemu" --version | sed -n 's/.*version \([0-9]*\)\..*/\1/p')
[ "${qemu_version:-0}" -ge 8 ] || bad "qemu-arm $qemu_version: 8 or later is needed (TCGETS2)"
# The vehicle as tests and benches start it: one program, arguments after.
vehicle="$PWD/target/armhf-vehicle"
cat >"$vehicle" <<EOF
#!/bin/sh
exec "$qemu" -cpu cortex-a8 -L /usr/arm-linux-gnueabihf "$PWD/$bin" "\$@"
EOF
chmod +x "$vehicle"
if "$vehicle" --version | grep -q '^neptunus '; then ok "runs under qemu-arm -cpu cortex-a8: $("$vehicle" --version)"; else bad "$vehicle --version"; fi

echo "== armhf: --sim under qemu-arm (pymavlink, mavlink2rest, the HMI page)"
venv=target/interop-venv
t0=$(date +%s)
rm -f target/armhf-junit.xml
if NEPTUNUS_BIN="$vehicle" "$venv/bin/python" -m pytest \
    "tests/interop/test_pymavlink.py::test_heartbeat_and_mode_mapping" \
    "tests/interop/test_pymavlink.py::test_arm_modes_disarm" \
    "tests/interop/test_driving.py::test_pymavlink_manual_control_drives_forward_yaws_and_disarm_stops" \
    "tests/interop/test_mavlink2rest.py::test_rest_reads_the_live_attitude_and_the_vehicle_heartbeat" \
    "tests/interop/test_mavlink2rest.py::test_cockpit_arms_dives_and_disarms_over_the_websocket" \
    tests/interop/test_hmi_page.py \
    -q -p no:cacheprovider --timeout 300 --junitxml target/armhf-junit.xml; then
    ok "--sim: 6 interoperability tests ($(($(date +%s) - t0)) s)"
else
    bad "--sim interoperability tests under qemu-arm"
fi

echo "== armhf: the genuine 30.0.2 firmware in simavr, the vehicle under qemu-arm"
t0=$(date +%s)
if NEPTUNUS_ARMHF_VEHICLE="$vehicle" NEPTUNUS_ARMHF_BIN="$PWD/$bin" cargo test --locked --features hil \
    --test genuine_firmware -- --ignored --exact the_armhf_vehicle_under_qemu_drives_the_genuine_2015_firmware; then
    ok "the genuine firmware: arm, drive, dead-man ($(($(date +%s) - t0)) s)"
else
    bad "the genuine firmware with the armhf vehicle"
fi
echo "== armhf: the CPU budget bench's smoke run (benches/cpu_budget.rs; the figures: cargo bench)"
t0=$(date +%s)
# One camera path here: the smoke run shows the counting works end to end.
if NEPTUNUS_ARMHF_BIN="$PWD/$bin" NEPTUNUS_QEMU_ARM="$qemu" CPU_BUDGET_PATHS=mjpeg-page \
    cargo test --locked --features hil --bench cpu_budget 2>&1 | tee target/armhf-budget.txt \
    && grep -q '^method check' target/armhf-budget.txt && grep -q '^idle ' target/armhf-budget.txt \
    && grep -q '^mjpeg-page ' target/armhf-budget.txt; then
    ok "the CPU budget bench counts ($(($(date +%s) - t0)) s)"
else
    bad "the CPU budget bench's smoke run"
fi
echo "armhf: the whole step took $(($(date +%s) - started)) s"
finish
