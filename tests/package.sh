#!/usr/bin/env bash
# Builds the Debian package for this machine's architecture (cargo-deb) and
# checks it: contents and permissions (dpkg-deb -c), control data and
# conffiles (dpkg-deb -I), the maintainer scripts, the unit file
# (systemd-analyze verify, and its security exposure), the packaged
# configuration (neptunus --check), and the binary from the package running
# --sim with the packaged configuration against a temporary data directory
# until it is ready, then stopping cleanly on SIGTERM.
# Installs what it needs itself. Run from anywhere: bash tests/package.sh
# PACKAGE_PROFILE names the Cargo profile to build with (default release,
# what `cargo deb` ships; the test command checks the `package-check`
# profile's build, made as the development build is, to keep its time down).
set -euo pipefail
cd "$(dirname "$0")/.."

as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }
fail() { echo "package: FAIL: $*" >&2; exit 1; }

CARGO_DEB_VERSION=3.8.0
if ! cargo deb --version 2>/dev/null | grep -q "$CARGO_DEB_VERSION"; then
    cargo install cargo-deb --version "$CARGO_DEB_VERSION" --locked
fi
if ! command -v dpkg-deb >/dev/null || ! command -v systemd-analyze >/dev/null; then
    as_root apt-get update -q
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -q dpkg systemd
fi

profile="${PACKAGE_PROFILE:-release}"
echo "== package: cargo deb (profile $profile)"
rm -f target/debian/neptunus_*.deb
cargo deb --locked --profile "$profile"
deb=$(ls target/debian/neptunus_*.deb)
echo "$deb: $(stat -c %s "$deb") bytes (the binary: $(stat -c %s "target/$profile/neptunus") bytes)"

echo "== package: control data"
info=$(dpkg-deb -I "$deb")
echo "$info"
grep -q '^ Package: neptunus$' <<<"$info" || fail "no Package: neptunus"
grep -q "^ Architecture: $(dpkg --print-architecture)$" <<<"$info" || fail "not built for $(dpkg --print-architecture)"
grep -Eq '^ Depends: .*adduser' <<<"$info" || fail "Depends lacks adduser (postinst uses it)"
conffiles=$(dpkg-deb --ctrl-tarfile "$deb" | tar -xO ./conffiles)
[ "$conffiles" = "/etc/neptunus/neptunus.toml" ] || fail "conffiles is '$conffiles', not /etc/neptunus/neptunus.toml"

echo "== package: contents and permissions"
contents=$(dpkg-deb -c "$deb")
echo "$contents"
has() { grep -Eq "^$1 (root/root|0/0) +[0-9]+ [0-9-]+ [0-9:]+ \./$2$" <<<"$contents" || fail "no $2 with mode $1 owned by root"; }
has '-rwxr-xr-x' 'usr/bin/neptunus'
has '-rw-r--r--' 'etc/neptunus/neptunus.toml'
has '-rw-r--r--' '(usr/)?lib/systemd/system/neptunus.service'
if grep -Eq '/var/lib/neptunus' <<<"$contents"; then fail "the package must not ship /var/lib/neptunus (StateDirectory makes it)"; fi

work=$(mktemp -d)
child=""
cleanup() {
    if [ -n "$child" ]; then kill "$child" 2>/dev/null || true; fi
    rm -rf "$work"
}
trap cleanup EXIT
dpkg-deb -x "$deb" "$work/root"
dpkg-deb -e "$deb" "$work/DEBIAN"
bin="$work/root/usr/bin/neptunus"
conf="$work/root/etc/neptunus/neptunus.toml"
unit=""
for u in "$work"/root/usr/lib/systemd/system/neptunus.service "$work"/root/lib/systemd/system/neptunus.service; do
    if [ -f "$u" ]; then unit=$u; fi
done
[ -n "$unit" ] || fail "no neptunus.service in the package"

echo "== package: maintainer scripts"
for s in postinst prerm postrm; do
    [ -f "$work/DEBIAN/$s" ] || fail "no $s"
    sh -n "$work/DEBIAN/$s" || fail "$s is not valid sh"
    if grep -q '#DEBHELPER#' "$work/DEBIAN/$s"; then fail "$s: #DEBHELPER# not replaced"; fi
done
grep -q 'adduser --system' "$work/DEBIAN/postinst" || fail "postinst does not make the neptunus user"
grep -Eq 'adduser neptunus "\$group"' "$work/DEBIAN/postinst" || fail "postinst does not add neptunus to dialout/video"
grep -q 'deb-systemd-helper enable neptunus.service' "$work/DEBIAN/postinst" || fail "postinst does not enable the service"
grep -q 'deb-systemd-invoke $_dh_action neptunus.service' "$work/DEBIAN/postinst" || fail "postinst does not (re)start the service"
grep -q 'rm -rf /var/lib/neptunus' "$work/DEBIAN/postrm" || fail "postrm does not remove the data on purge"

echo "== package: the unit (systemd-analyze verify)"
# verify checks that ExecStart's program exists: point the unit at the
# extracted binary (the only change), in a folder of its own.
mkdir "$work/unit"
sed "s#/usr/bin/neptunus#$bin#g" "$unit" >"$work/unit/neptunus.service"
# It exits 0 on unknown keys and bad values (only warning): any output fails.
verify=$(cd "$work/unit" && systemd-analyze verify ./neptunus.service 2>&1) || fail "systemd-analyze verify: $verify"
[ -z "$verify" ] || fail "systemd-analyze verify warns: $verify"
echo "systemd-analyze verify: clean"
# One capability, the one that binds port 80 (Cockpit's vehicle address).
for want in 'Type=notify' 'WatchdogSec=' 'Restart=always' 'NoNewPrivileges=yes' 'ProtectSystem=strict' \
    'ProtectHome=yes' 'PrivateTmp=yes' 'CapabilityBoundingSet=CAP_NET_BIND_SERVICE$' \
    'AmbientCapabilities=CAP_NET_BIND_SERVICE$' 'StateDirectory=neptunus' 'User=neptunus' \
    'MemoryMax=' 'TasksMax='; do
    grep -Eq "^$want" "$unit" || fail "the unit lacks $want"
done
score=$(systemd-analyze security --offline=true "$unit" 2>/dev/null | sed -n 's/.*Overall exposure level for neptunus.service: \([0-9.]*\).*/\1/p')
echo "systemd-analyze security: exposure $score (0 = most locked down, 10 = none)"
[ -n "$score" ] || fail "no systemd-analyze security score"
awk -v s="$score" 'BEGIN { exit !(s <= 2.0) }' || fail "exposure $score is above 2.0: the hardening regressed"

echo "== package: the packaged configuration"
"$bin" --config "$conf" --check || fail "the packaged configuration does not parse"
grep -q '^http = "0.0.0.0:80"$' "$conf" || fail "the packaged configuration does not put the HMI on port 80 (Cockpit's vehicle address)"
# Its commented examples ([camera.ffmpeg], [camera.h264], [camera.webrtc]) parse once uncommented.
sed 's/^# \(\[camera\.\|input_args\|passthrough\|enabled\|ice_servers\)/\1/' "$conf" >"$work/examples.toml"
cmp -s "$conf" "$work/examples.toml" && fail "no commented example found in the packaged configuration"
"$bin" --config "$work/examples.toml" --check >/dev/null || fail "a commented example in the packaged configuration does not parse"

echo "== package: the packaged binary runs --sim with the packaged configuration"
data="$work/data"
# Flags over the file: loopback ports picked by the system, so tests running
# side by side (and a vehicle on this machine) do not collide.
RUST_LOG=info "$bin" --config "$conf" --sim --data-dir "$data" \
    --mavlink udpin:127.0.0.1:0 --http 127.0.0.1:0 --video-rtp off \
    >"$work/stdout" 2>"$work/stderr" &
child=$!
up=""
for _ in $(seq 1 300); do
    if ! kill -0 "$child" 2>/dev/null; then
        cat "$work/stderr" >&2
        fail "the packaged binary exited"
    fi
    if [ -f "$data/http.addr" ] && grep -q 'board link up' "$work/stderr"; then up=1; break; fi
    sleep 0.1
done
[ -n "$up" ] || { tail -20 "$work/stderr" >&2; fail "no HMI address and board link within 30 s"; }
kill -TERM "$child"
status=0
wait "$child" || status=$?
child=""
[ "$status" = 0 ] || { tail -20 "$work/stderr" >&2; fail "exit status $status after SIGTERM"; }
grep -q 'thrusters to neutral' "$work/stderr" || fail "no 'thrusters to neutral' at shutdown"
ls "$data"/tlogs/neptunus-*.tlog >/dev/null || fail "no tlog in the temporary data directory"
echo "== package: with the service's one capability, an unprivileged user binds port 80"
# As systemd starts it (User=neptunus, AmbientCapabilities=CAP_NET_BIND_SERVICE,
# NoNewPrivileges): the packaged binary and configuration, as nobody, with
# the HMI on port 80 of a loopback address of its own; then without the
# capability, which must fail and say why.
if [ "$(id -u)" != 0 ] || ! command -v setpriv >/dev/null; then
    fail "this step needs root and setpriv (util-linux) to start the binary as an unprivileged user"
fi
chmod 755 "$work"
addr="127.0.0.$(( (RANDOM % 200) + 20 ))"
data80="$work/data80"
mkdir "$data80"
chown nobody "$data80"
# exec: in the background (&) the function's subshell becomes the vehicle,
# so $! is the vehicle's own process id.
as_service() {
    exec setpriv --reuid=nobody --regid="$(id -g nobody)" --clear-groups --no-new-privs "$@" -- \
        "$bin" --config "$conf" --sim --data-dir "$data80" --mavlink udpin:127.0.0.1:0 \
        --http "$addr:80" --video-rtp off --webrtc off
}
as_service --inh-caps=-all,+net_bind_service --ambient-caps=-all,+net_bind_service \
    --bounding-set=-all,+net_bind_service >"$work/stdout80" 2>"$work/stderr80" &
child=$!
up=""
for _ in $(seq 1 300); do
    if ! kill -0 "$child" 2>/dev/null; then
        cat "$work/stderr80" >&2
        fail "the packaged binary as nobody with CAP_NET_BIND_SERVICE exited"
    fi
    if grep -qx "$addr:80" "$data80/http.addr" 2>/dev/null; then up=1; break; fi
    sleep 0.1
done
[ -n "$up" ] || { tail -20 "$work/stderr80" >&2; fail "no HMI on $addr:80 within 30 s"; }
exec 3<>"/dev/tcp/$addr/80"
printf 'GET /bag/v1.0/get/cockpit/cockpit-vehicle-id HTTP/1.0\r\nHost: %s\r\n\r\n' "$addr" >&3
reply=$(cat <&3)
exec 3<&-
grep -q '"Invalid path"' <<<"$reply" || fail "port 80 does not answer the settings bag: $reply"
kill -TERM "$child"
wait "$child" || true
kill -0 "$child" 2>/dev/null && fail "the vehicle on port 80 did not stop on SIGTERM"
child=""
status=0
(as_service --inh-caps=-all --ambient-caps=-all --bounding-set=-all) >/dev/null 2>"$work/stderr80" || status=$?
[ "$status" != 0 ] || fail "the binary bound port 80 without the capability"
grep -q 'CAP_NET_BIND_SERVICE' "$work/stderr80" || { cat "$work/stderr80" >&2; fail "refused port 80 without saying which capability it needs"; }
echo "port 80: bound with CAP_NET_BIND_SERVICE as nobody, refused without it (and the error names the capability)"
echo "package: 1 passed, 0 failed"
