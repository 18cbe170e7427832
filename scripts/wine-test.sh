#!/usr/bin/env bash
# Runs the Windows backend's test suite under Wine: cross-builds arena-guest.exe,
# arena-guest-logon.exe (the logon task's launcher, found beside it) and
# arena-input-recorder.exe (the input catalogue's recorder window, beside them too),
# starts a virtual display and a private Wine prefix, then runs tests/tests/wine.rs,
# which drives the exe with the real host client (the input catalogue included), and
# tests/tests/wine_prep.rs.
#
# Usage: scripts/wine-test.sh [--release] [--no-build] [--host] [-- TEST-ARGS...]
#
# TEST-ARGS go to the test binaries (a name filter such as input_catalogue, --exact).
#
# --host also cross-builds arena-vm's unit tests and runs its Windows-only ones under
# Wine (an exec agent's job object: child::windows). That builds arena-vm and its
# dependencies for Windows, minutes on 2 cores, so it is not done by default.
#
# Environment (all optional):
#   DISPLAY             an X display to use; default: starts Xvfb on :99 (1440x900x24)
#   WINEPREFIX          the Wine prefix; default: target/wine-prefix (created once, ~15 s)
#   ARENA_REQUIRE_WINE  1 (default here) makes a suite that cannot run a failure
#
# Run as root on a fresh machine, it installs wine, wine64 and xvfb when missing
# (scripts/build-windows.sh installs the cross toolchain the same way).
set -euo pipefail

cd "$(dirname "$0")/.."
ROOT=$PWD
BUILD=1
PROFILE=debug
HOST=0
TEST_ARGS=()
while [ "$#" -gt 0 ]; do
    arg=$1
    shift
    case "$arg" in
        --) TEST_ARGS=("$@"); break ;;
        --no-build) BUILD=0 ;;
        --host) HOST=1 ;;
        --release) PROFILE=release ;;
        -h|--help) sed -n '2,23p' "$0"; exit 0 ;;
        *) echo "unknown argument: $arg" >&2; exit 2 ;;
    esac
done

missing=()
for pkg in wine wine64 xvfb; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done
if [ "${#missing[@]}" -gt 0 ]; then
    if [ "$(id -u)" = 0 ]; then
        echo "installing ${missing[*]}"
        DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${missing[@]}" \
            || { apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${missing[@]}"; }
    else
        echo "missing Debian packages: ${missing[*]} (run as root, or: apt-get install ${missing[*]})" >&2
        exit 1
    fi
fi

TARGET_DIR="$ROOT/target/windows"
EXE="$TARGET_DIR/x86_64-pc-windows-gnu/$PROFILE/arena-guest.exe"
LAUNCHER="$TARGET_DIR/x86_64-pc-windows-gnu/$PROFILE/arena-guest-logon.exe"
RECORDER="$TARGET_DIR/x86_64-pc-windows-gnu/$PROFILE/arena-input-recorder.exe"
SHIM="$TARGET_DIR/wine/bcryptprimitives.dll"
if [ "$BUILD" = 1 ]; then
    if [ "$PROFILE" = release ]; then scripts/build-windows.sh --release; else scripts/build-windows.sh; fi
fi
for f in "$EXE" "$LAUNCHER" "$RECORDER" "$SHIM"; do
    [ -f "$f" ] || { echo "$f is missing: run scripts/build-windows.sh" >&2; exit 1; }
done

XVFB_PID=""
cleanup() {
    # Only what this script started: the prefix's own wineserver and our Xvfb.
    WINEPREFIX="$WINEPREFIX" wineserver -k 2>/dev/null || true
    if [ -n "$XVFB_PID" ]; then
        kill "$XVFB_PID" 2>/dev/null || true
    fi
}

if [ -z "${DISPLAY:-}" ]; then
    export DISPLAY=:99
    if [ ! -S /tmp/.X11-unix/X99 ]; then
        Xvfb :99 -screen 0 1440x900x24 -nolisten tcp >"$ROOT/target/xvfb.log" 2>&1 &
        XVFB_PID=$!
        for _ in $(seq 50); do [ -S /tmp/.X11-unix/X99 ] && break; sleep 0.1; done
    fi
fi

export WINEPREFIX="${WINEPREFIX:-$ROOT/target/wine-prefix}"
export WINEDLLOVERRIDES="mscoree,mshtml="
export WINEDEBUG="${WINEDEBUG:--all}"
export WINEARCH=win64
trap cleanup EXIT

if [ ! -f "$WINEPREFIX/system.reg" ]; then
    echo "creating the Wine prefix $WINEPREFIX"
    started=$(date +%s)
    timeout 180 wineboot -i >/dev/null 2>&1 || true
    wineserver -w
    echo "prefix ready in $(( $(date +%s) - started )) s"
fi
# A clean desktop: end what an earlier run of this prefix left open.
wineserver -k 2>/dev/null || true
cp "$SHIM" "$WINEPREFIX/drive_c/windows/system32/bcryptprimitives.dll"

export ARENA_WINDOWS_EXE="$EXE"
export ARENA_WINE="${ARENA_WINE:-$(command -v wine)}"
export ARENA_REQUIRE_WINE="${ARENA_REQUIRE_WINE:-1}"
started=$(date +%s)
# --workspace: the features of the workspace's test build, so nothing is rebuilt
# after ./test.sh (with -p arena-tests cargo resolves other features and rebuilds).
cargo test --workspace --test wine --test wine_prep -- --nocapture "${TEST_ARGS[@]}"
echo "wine suite took $(( $(date +%s) - started )) s"

if [ "$HOST" = 1 ]; then
    # Debian's toolchain, as scripts/build-windows.sh uses it, with Wine as the runner.
    started=$(date +%s)
    PATH="/usr/bin:$PATH" RUSTC=/usr/bin/rustc RUSTDOC=/usr/bin/rustdoc RUSTC_BOOTSTRAP=1 \
        CARGO_TARGET_X86_64_PC_WINDOWS_GNU_LINKER=x86_64-w64-mingw32-gcc \
        CARGO_TARGET_X86_64_PC_WINDOWS_GNU_RUNNER="$ARENA_WINE" CARGO_TARGET_DIR="$TARGET_DIR" \
        /usr/bin/cargo test -p arena-vm --lib --target x86_64-pc-windows-gnu -Zbuild-std=std,panic_abort --locked \
        -- child::windows
    echo "host tests under Wine took $(( $(date +%s) - started )) s"
fi
