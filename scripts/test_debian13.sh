#!/usr/bin/env bash
# Runs the README's `make test` on Debian 13 (trixie: QGIS 3.40, Python 3.13, numpy 2.2) in a
# Debian 13 root built with debootstrap from Debian's archive, with this repository mounted at the
# same path inside it. Needs root (debootstrap, chroot, mounts) and Debian's archive.
#
# The root is cached between runs outside the clone (FLOODMESH_TRIXIE_ROOT, by default
# /var/cache/floodmesh/trixie-root): the first run spends a few minutes on debootstrap and QGIS's
# packages, later runs only `make test`. FLOODMESH_TRIXIE_REBUILD=1 builds it afresh.
# All mounts live in a private mount namespace (unshare), so they vanish with it however the run
# ends; the trap below unmounts them too. Arguments are passed to pytest (as for scripts/test.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
REPO=$(pwd -P)
ROOT=${FLOODMESH_TRIXIE_ROOT:-/var/cache/floodmesh/trixie-root}
MIRROR=${FLOODMESH_DEBIAN_MIRROR:-http://deb.debian.org/debian}
# What a new user installs on a fresh Debian 13 before cloning (setup.sh installs the rest).
BASE_PACKAGES=(git make ca-certificates python3)

if [ "$(id -u)" -ne 0 ]; then
    echo "test_debian13: needs root (debootstrap, chroot and mounts); run it with sudo" >&2
    exit 2
fi
if ! command -v debootstrap >/dev/null; then
    echo "test_debian13: installing debootstrap"
    # apt is shared with anything else installing on this machine: wait for it
    flock /tmp/apt.lock apt-get install -y -qq --no-install-recommends debootstrap >/dev/null \
        || { flock /tmp/apt.lock apt-get update -qq && flock /tmp/apt.lock apt-get install -y -qq \
                 --no-install-recommends debootstrap >/dev/null; }
fi

in_root() {  # run a command in the root, with /proc, /dev and /sys (only for the build steps)
    unshare --mount --propagation private bash -euc '
        root=$1; shift
        mount -t proc proc "$root/proc"; mount --rbind /dev "$root/dev"; mount --rbind /sys "$root/sys"
        exec chroot "$root" /usr/bin/env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin HOME=/root \
            DEBIAN_FRONTEND=noninteractive LANG=C.UTF-8 "$@"' _ "$ROOT" "$@"
}

build_root() {  # debootstrap into a temporary folder, renamed when complete: never a half root
    local tmp="$ROOT.building"
    rm -rf --one-file-system "$tmp"
    mkdir -p "$(dirname "$ROOT")"
    echo "test_debian13: building a Debian 13 root in $ROOT (debootstrap trixie, a few minutes)"
    debootstrap --variant=minbase trixie "$tmp" "$MIRROR" >"$tmp.log" 2>&1 || {
        tail -20 "$tmp.log" >&2; echo "test_debian13: debootstrap failed (log: $tmp.log)" >&2; exit 1; }
    printf '#!/bin/sh\nexit 101\n' >"$tmp/usr/sbin/policy-rc.d"; chmod +x "$tmp/usr/sbin/policy-rc.d"
    cp /etc/resolv.conf "$tmp/etc/resolv.conf"
    rm -rf --one-file-system "$ROOT"
    mv "$tmp" "$ROOT"
    in_root apt-get -o Acquire::Retries=3 update -qq
    in_root apt-get -o Acquire::Retries=3 install -y -qq --no-install-recommends \
        "${BASE_PACKAGES[@]}" >/dev/null
    touch "$ROOT/.floodmesh-ready"
}

# One run at a time builds or changes the root (CI and a developer may share the machine).
mkdir -p "$(dirname "$ROOT")"
exec 9>"$ROOT.lock"
flock 9
if [ "${FLOODMESH_TRIXIE_REBUILD:-0}" = 1 ] || [ ! -f "$ROOT/.floodmesh-ready" ]; then
    build_root
fi
# The machine's network settings go in with each run: its DNS and its site CAs (a proxy's,
# for Debian's archive and PyPI), and the proxy variables below.
cp /etc/resolv.conf "$ROOT/etc/resolv.conf"
if [ -d /usr/local/share/ca-certificates ] && ! diff -rq /usr/local/share/ca-certificates \
        "$ROOT/usr/local/share/ca-certificates" >/dev/null 2>&1; then
    rm -rf "$ROOT/usr/local/share/ca-certificates"
    cp -a /usr/local/share/ca-certificates "$ROOT/usr/local/share/ca-certificates"
    in_root update-ca-certificates >/dev/null
fi
passed=()
for name in http_proxy https_proxy no_proxy HTTP_PROXY HTTPS_PROXY NO_PROXY PIP_INDEX_URL \
            PIP_DEFAULT_TIMEOUT CI; do
    if [ -n "${!name:-}" ]; then passed+=("$name=${!name}"); fi
done
echo "test_debian13: $(chroot "$ROOT" cat /etc/debian_version) root at $ROOT, repository at $REPO"

# The repository appears at its own path inside the root, so the plugin link and editable install
# name the same folder on both sides. Its .venv is Debian 12's: inside, a venv of the root's own
# (one per clone path, kept in the root) is mounted over it; the same for .venv-flood (ANUGA's).
# Each run starts from an empty /tmp, home folder (QGIS profile, caches) included, so that
# nothing a previous run left changes this one's answer; pip's download cache is kept.
rm -rf --one-file-system "$ROOT/tmp"
mkdir -m 1777 "$ROOT/tmp"
venv="$ROOT/var/lib/floodmesh/venvs/$(printf %s "$REPO" | sha1sum | cut -c1-12)"
mkdir -p "$venv" "$venv-flood" "$REPO/.venv" "$REPO/.venv-flood" "$ROOT$REPO"
shared=""
[ -e "$REPO/../shared" ] && shared=$(cd "$REPO/../shared" && pwd -P)
# a git worktree keeps its repository elsewhere: mount that too (read-only), for git ls-files
gitdir=$(git -C "$REPO" rev-parse --path-format=absolute --git-common-dir 2>/dev/null || true)
case "$gitdir" in "$REPO"/*|"") gitdir="" ;; *) mkdir -p "$ROOT$gitdir" ;; esac

unshare --mount --propagation private bash -euc '
    root=$1 repo=$2 venv=$3 shared=$4 passed=$5 gitdir=$6; shift 6
    cleanup() { umount -R "$root/proc" "$root/dev" "$root/sys" "$root$repo" 2>/dev/null || true; }
    trap cleanup EXIT
    mount -t proc proc "$root/proc"; mount --rbind /dev "$root/dev"; mount --rbind /sys "$root/sys"
    mount --bind "$repo" "$root$repo"
    mount --bind "$venv" "$root$repo/.venv"
    mount --bind "$venv-flood" "$root$repo/.venv-flood"
    if [ -n "$gitdir" ]; then
        mount --bind "$gitdir" "$root$gitdir"; mount -o remount,bind,ro "$root$gitdir"
    fi
    if [ -n "$shared" ]; then
        mkdir -p "$root$shared"; mount --bind "$shared" "$root$shared"
        [ "$shared" = "$(dirname "$repo")/shared" ] || ln -sfn "$shared" "$root$(dirname "$repo")/shared"
    fi
    chroot "$root" /usr/bin/env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin HOME=/tmp/home LANG=C.UTF-8 \
        PIP_CACHE_DIR=/var/cache/pip XDG_RUNTIME_DIR=/tmp/runtime \
        DEBIAN_FRONTEND=noninteractive $passed bash -c "mkdir -p -m 700 /tmp/home /tmp/runtime && cd \"\$0\" && make setup && exec bash scripts/test.sh \"\$@\"" "$repo" "$@"
' _ "$ROOT" "$REPO" "$venv" "$shared" "${passed[*]:-}" "$gitdir" "$@"
