#!/usr/bin/env bash
# Runs every Neptunus test on a fresh machine: installs what the tests need,
# then checks formatting and lints, then runs the whole test suite.
# This is the README's test command; .ci/run calls exactly this.
set -euo pipefail
cd "$(dirname "$0")/.."

echo "== toolchain"
cargo --version
rustc --version

as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }

echo "== test tools"
# The camera tests run a real ffmpeg (tests/camera.rs).
if ! command -v ffmpeg >/dev/null 2>&1; then
    as_root apt-get update -q
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -q ffmpeg
fi
ffmpeg -hide_banner -version | sed -n 1p

echo "== formatting and lints"
cargo fmt --all -- --check
cargo clippy --all-targets --locked -- -D warnings

echo "== tests"
status=0
cargo test --all-targets --locked 2>&1 | tee target/test-output.txt || status=1

echo "== interoperability tests (real ground-station clients against the binary)"
# A venv in target/ with the pinned clients; reinstalled when the pins change.
venv=target/interop-venv
reqs=tests/interop/requirements.txt
if ! python3 -c 'import ensurepip, venv' 2>/dev/null; then
    # Debian/Ubuntu split venv/ensurepip out of the interpreter package.
    as_root apt-get update -q && as_root apt-get install -y -q python3-venv
fi
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
fi
if ! cmp -s "$reqs" "$venv/requirements.installed"; then
    "$venv/bin/python" -m pip install -q --disable-pip-version-check -r "$reqs"
    cp "$reqs" "$venv/requirements.installed"
fi
# MAVProxy pulls in opencv-python, which needs libGL and glib at import time.
if ! "$venv/bin/python" -c 'import cv2' 2>/dev/null; then
    as_root apt-get update -q && as_root apt-get install -y -q libgl1 libglib2.0-0
fi
cargo build --locked
test -x target/debug/neptunus
rm -f target/interop-junit.xml
NEPTUNUS_BIN="$PWD/target/debug/neptunus" "$venv/bin/python" -m pytest tests/interop -q \
    -p no:cacheprovider --timeout 300 --junitxml target/interop-junit.xml || status=1

# Summarise as one plain line for CI: cargo prints one result line per test
# binary; pytest's counts come from its JUnit XML.
read -r py_pass py_fail py_skip < <("$venv/bin/python" - target/interop-junit.xml <<'PY' || echo "0 1 0"
import sys, xml.etree.ElementTree as ET
try:
    root = ET.parse(sys.argv[1]).getroot()
except (OSError, ET.ParseError):
    print(0, 1, 0)  # pytest did not even produce a report: count it as a failure
    raise SystemExit
suites = [root] if root.tag == "testsuite" else root.findall("testsuite")
t = sum(int(s.get("tests", 0)) for s in suites)
f = sum(int(s.get("failures", 0)) + int(s.get("errors", 0)) for s in suites)
k = sum(int(s.get("skipped", 0)) for s in suites)
print(t - f - k, f, k)
PY
)
awk -v pp="$py_pass" -v pf="$py_fail" -v ps="$py_skip" \
    '/^test result:/ { p += $4; f += $6; i += $8 } END { printf "tests: %d passed, %d failed, %d skipped\n", p + pp, f + pf, i + ps }' \
    target/test-output.txt
exit "$status"
