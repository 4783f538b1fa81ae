#!/usr/bin/env bash
# Run the README's two commands exactly as written in a fresh root of another Debian release, as a new user there
# would: by default Debian 13 "trixie" (Python 3.13, g++ 14, libhwy-dev 1.2). tests/install/test_distro.py runs it.
#
#   scripts/check_distro.sh [SUITE]        (SUITE: trixie)
#
# Needs root (debootstrap, chroot, mounts) and the network to Debian's archive and the package index. The root is
# made by `debootstrap --variant=minbase` on first use in GBVIEWER_DISTRO_ROOT (default
# ~/.cache/gbviewer/distro-SUITE) and kept: a second run finds Debian's packages, pip's cache and the build there. Each
# run copies this checkout's files (git's tracked and untracked-not-ignored ones) to /work/main inside, and ../shared
# beside it when present, then runs, with a clean environment and no display:
#   bash scripts/setup.sh && .venv/bin/gbviewer           (writes out/comparison.png and out/zoom.mp4)
#   bash scripts/setup.sh --dev && .venv/bin/pytest -q
# and reports the Python, the compiler, Highway's version, the SIMD path selected, what the main job wrote and the
# tests' summary line (the whole log: SUITE.log beside the root). Exit status 0 when both commands exit 0 and the
# comparison image and zoom video are written, 1 when not, 3 (one line) when root or debootstrap is missing.
set -euo pipefail
cd "$(dirname "$0")/.."
SUITE=${1:-trixie}
CACHE=${XDG_CACHE_HOME:-$HOME/.cache}/gbviewer
ROOTFS=${GBVIEWER_DISTRO_ROOT:-$CACHE/distro-$SUITE}
LOG=$ROOTFS.log
say() { echo "check_distro: $*"; }
[ "$(id -u)" = 0 ] || { say "needs root (debootstrap, chroot and mounts)"; exit 3; }
command -v debootstrap >/dev/null || { say "missing debootstrap: apt-get install debootstrap"; exit 3; }

if [ ! -e "$ROOTFS/.gbviewer-root" ]; then
  tmp="$ROOTFS.tmp"
  rm -rf "$tmp" && mkdir -p "$(dirname "$ROOTFS")"
  say "making a Debian $SUITE root in $ROOTFS (debootstrap, a few minutes)"
  # git: the user cloned the checkout with it (and tests list its tracked files)
  debootstrap --variant=minbase --include=ca-certificates,git "$SUITE" "$tmp" http://deb.debian.org/debian \
    > "$tmp.log" 2>&1 || { tail -5 "$tmp.log"; say "debootstrap failed ($tmp.log)"; exit 1; }
  touch "$tmp/.gbviewer-root" && rm -rf "$ROOTFS" && mv "$tmp" "$ROOTFS" && rm -f "$tmp.log"
fi
cp /etc/resolv.conf "$ROOTFS/etc/resolv.conf"
# the certificate authorities this machine adds to Debian's (a network's TLS proxy, say): a machine on this network
# trusts them too
if compgen -G "/usr/local/share/ca-certificates/*.crt" >/dev/null; then
  mkdir -p "$ROOTFS/usr/local/share/ca-certificates"
  cp /usr/local/share/ca-certificates/*.crt "$ROOTFS/usr/local/share/ca-certificates/"
  chroot "$ROOTFS" update-ca-certificates >/dev/null 2>&1 || { say "update-ca-certificates failed in the root"; exit 1; }
fi

[ -x "$ROOTFS/usr/bin/git" ] || chroot "$ROOTFS" /usr/bin/env -i PATH=/usr/bin:/bin DEBIAN_FRONTEND=noninteractive \
  bash -c "apt-get update -qq && apt-get install -y -qq git" >/dev/null 2>&1 || { say "could not install git in the root"; exit 1; }

mounted=()
cleanup() { for ((i = ${#mounted[@]} - 1; i >= 0; i--)); do umount -l "${mounted[i]}" 2>/dev/null || true; done; }
trap cleanup EXIT
trap 'exit 130' INT TERM  # a killed run unmounts too (the EXIT trap runs)
# a run killed before its cleanup (SIGKILL) leaves its mounts: take them down before mounting again
mnt() {
  mkdir -p "${@: -1}" && { ! mountpoint -q "${@: -1}" || umount -l "${@: -1}"; } && mount "$@" && mounted+=("${@: -1}")
}
mnt -t proc proc "$ROOTFS/proc"
mnt -t sysfs sys "$ROOTFS/sys"
mnt --bind /dev "$ROOTFS/dev"
mnt -t devpts devpts "$ROOTFS/dev/pts"
mnt -t tmpfs shm "$ROOTFS/dev/shm"

# the checkout as a clone would have it, with no venv; the build folder of an earlier run stays, and so do pip's
# cache and Debian's packages in the root (a second run is quick)
work="$ROOTFS/work/main"
mkdir -p "$work"
find "$work" -mindepth 1 -maxdepth 1 ! -name build -exec rm -rf {} +
if git rev-parse --is-inside-work-tree >/dev/null 2>&1; then
  git ls-files -z --cached --others --exclude-standard | tar --null -T - -cf - | tar -C "$work" -xf -
else
  tar --exclude=./.venv --exclude=./build --exclude=./out -cf - . | tar -C "$work" -xf -
fi
# a git repository with those files, as a clone is (tests list its tracked files)
git -C "$work" init -q && git -C "$work" add -A &&
  git -C "$work" -c user.name=check_distro -c user.email=check_distro@localhost commit -qm "the checkout" ||
  { say "could not make the checkout's copy a git repository"; exit 1; }
rm -rf "$ROOTFS/work/shared"
[ -d ../shared ] && cp -a ../shared "$ROOTFS/work/shared"

inside() {
  chroot "$ROOTFS" /usr/bin/env -i HOME=/root PATH=/usr/local/bin:/usr/bin:/bin LANG=C.UTF-8 TERM=dumb \
    GBVIEWER_IN_DISTRO_CHECK=1 bash -c "cd /work/main && $1"
}
: > "$LOG"
status=0
say "Debian $(cat "$ROOTFS/etc/debian_version") ($SUITE): bash scripts/setup.sh && .venv/bin/gbviewer"
inside "bash scripts/setup.sh && .venv/bin/gbviewer" >> "$LOG" 2>&1 || { status=1; say "the first command failed"; }
for f in out/comparison.png out/zoom.mp4; do
  [ -s "$work/$f" ] && say "wrote $f ($(stat -c %s "$work/$f") bytes)" || { status=1; say "no $f"; }
done
say "$(inside ".venv/bin/python -c 'import platform; print(\"Python\", platform.python_version())'" 2>&1); $(inside \
  "c++ --version | head -1" 2>&1); Highway $(inside "dpkg-query -W -f '\${Version}' libhwy-dev" 2>&1)"
say "$(inside ".venv/bin/gbviewer info | head -1" 2>&1); the venv after the first command: $(inside \
  "du -sh .venv | cut -f1" 2>&1)"
say "bash scripts/setup.sh --dev && .venv/bin/pytest -q"
inside "bash scripts/setup.sh --dev && .venv/bin/pytest -q" >> "$LOG" 2>&1 ||
  { status=1; say "the test command failed"; }
grep -E "^(setup: torch|[0-9]+ (passed|failed)|FAILED|ERROR)" "$LOG" | tail -40 | sed 's/^/check_distro: /'
# where each failure failed and what it said: pytest's summary line cuts the message at the terminal's width
grep -E "^(E   |[A-Za-z0-9_./-]+\.py:[0-9]+: [A-Za-z]*(Error|Exception))" "$LOG" | head -40 | sed 's/^/check_distro: /' || true
say "log: $LOG"
exit $status
