#!/usr/bin/env bash
# Builds the BeagleBone's Debian package (armhf, armv7-unknown-linux-gnueabihf)
# on a Debian 12 (bookworm) x86_64 machine, installing the toolchain itself:
# Debian's Rust 1.96 (rustc-web, cargo-web from bookworm-security) rebuilds
# the standard library for the target from its sources (rust-web-src,
# `-Z build-std`), and Debian's cross gcc links against the cross glibc
# 2.36. No rustup target and nothing outside Debian's archive and crates.io.
# The test command runs exactly this (tests/armhf.sh); the guide's
# "Installing on the ROV" gives it to owners.
#
#   bash debian/build-armhf.sh
#   -> target/armv7-unknown-linux-gnueabihf/debian/neptunus_<version>_armhf.deb
#   bash debian/build-armhf.sh --toolchain-only   (installs, builds nothing)
#   bash debian/build-armhf.sh --packages-only    (only Debian's packages)
#
# The profile `rov` (Cargo.toml) is the release profile without link-time
# optimisation. No npm: the page's plotting library comes from
# NEPTUNUS_UPLOT_DIR when set (web/README.md), else from web/node_modules.
set -euo pipefail
cd "$(dirname "$0")/.."

as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }

target=armv7-unknown-linux-gnueabihf
profile=rov
packages="rustc-web cargo-web rust-web-src gcc-arm-linux-gnueabihf libc6-dev-armhf-cross"
missing=""
for p in $packages; do
    dpkg -s "$p" >/dev/null 2>&1 || missing="$missing $p"
done
if [ -n "$missing" ]; then
    as_root apt-get update -q
    # shellcheck disable=SC2086 # one word per package
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -q $missing
fi
if [ "${1:-}" = --packages-only ]; then
    exit 0
fi
CARGO_DEB_VERSION=3.8.0
if ! cargo deb --version 2>/dev/null | grep -q "$CARGO_DEB_VERSION"; then
    cargo install cargo-deb --version "$CARGO_DEB_VERSION" --locked
fi
if [ "${1:-}" = --toolchain-only ]; then
    exit 0
fi

# Debian's rustc and cargo, whatever a rustup toolchain earlier in PATH is;
# RUSTC_BOOTSTRAP lets this stable compiler take `-Z build-std`.
/usr/bin/rustc --version
echo "== armhf: cargo build --profile $profile --target $target (build-std)"
RUSTC=/usr/bin/rustc RUSTC_BOOTSTRAP=1 \
    CARGO_TARGET_ARMV7_UNKNOWN_LINUX_GNUEABIHF_LINKER=arm-linux-gnueabihf-gcc \
    CC_armv7_unknown_linux_gnueabihf=arm-linux-gnueabihf-gcc \
    /usr/bin/cargo build --locked --profile "$profile" --target "$target" --bin neptunus \
    -Z build-std=std,panic_abort

echo "== armhf: cargo deb --no-build"
rm -f "target/$target/debian/"neptunus_*.deb
cargo deb --locked --no-build --no-strip --profile "$profile" --target "$target"
ls "target/$target/debian/"neptunus_*_armhf.deb
