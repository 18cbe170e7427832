#!/usr/bin/env bash
# Cross-builds the guest's two exes for x86_64-pc-windows-gnu on Debian: arena-guest.exe
# (the server, a console program, crate arena-guest) and arena-guest-logon.exe (the logon
# task's launcher, a GUI-subsystem program of its own small crate, arena-guest-launch in
# guest-server/launch/; they ship together), arena-input-recorder.exe (the window the input
# check records with, guest-server/recorder/, shipped beside them), and the
# bcryptprimitives.dll shim that lets
# Rust programs start under Wine 8. Then it type-checks the host crate, arena-host, for
# the same target with our crates' warnings denied (on a Windows host an exec agent runs
# in a job object: host-client/vm/src/child/windows/), in the same target folder.
#
# Usage: scripts/build-windows.sh [--release] [--no-install] [--no-host-check]
#
# The rustup toolchain on these machines has only the Linux standard library, so
# this uses Debian's Rust (/usr/bin/cargo, /usr/bin/rustc, the std source in
# /usr/lib/rustlib/src/rust) and builds std from source for the Windows target
# (-Zbuild-std, allowed on a stable compiler by RUSTC_BOOTSTRAP=1). The output goes
# to target/windows so it never fights the native build over target/debug.
#
# Run as root, it installs the Debian packages it needs when they are missing.
# Prints the exes' paths and sizes last; other scripts read the lines `exe: PATH` and
# `launcher: PATH` and `recorder: PATH`.
set -euo pipefail

cd "$(dirname "$0")/.."
ROOT=$PWD
PROFILE=debug
INSTALL=1
HOST_CHECK=1
for arg in "$@"; do
    case "$arg" in
        --release) PROFILE=release ;;
        --no-install) INSTALL=0 ;;
        --no-host-check) HOST_CHECK=0 ;;
        -h|--help) sed -n '2,20p' "$0"; exit 0 ;;
        *) echo "unknown argument: $arg" >&2; exit 2 ;;
    esac
done

TARGET=x86_64-pc-windows-gnu
PACKAGES=(rustc-web cargo-web rust-web-src gcc-mingw-w64-x86-64)

missing=()
for pkg in "${PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done
if [ "${#missing[@]}" -gt 0 ]; then
    if [ "$INSTALL" = 1 ] && [ "$(id -u)" = 0 ]; then
        echo "installing ${missing[*]}"
        DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${missing[@]}" \
            || { apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${missing[@]}"; }
    else
        echo "missing Debian packages: ${missing[*]} (run as root, or: apt-get install ${missing[*]})" >&2
        exit 1
    fi
fi

# Debian's toolchain, not rustup's: only it has the std source this build needs.
export PATH="/usr/bin:$PATH"
export RUSTC=/usr/bin/rustc
export RUSTDOC=/usr/bin/rustdoc
unset RUSTUP_TOOLCHAIN
export RUSTC_BOOTSTRAP=1
export CARGO_TARGET_X86_64_PC_WINDOWS_GNU_LINKER=x86_64-w64-mingw32-gcc
export CARGO_TARGET_DIR="$ROOT/target/windows"

args=(build -p arena-guest -p arena-guest-launch -p arena-input-recorder --bin arena-guest --bin arena-guest-logon
      --bin arena-input-recorder --target "$TARGET" -Zbuild-std=std,panic_abort)
if [ "$PROFILE" = release ]; then
    args+=(--release)
fi
started=$(date +%s)
/usr/bin/cargo "${args[@]}"
echo "cross build took $(( $(date +%s) - started )) s"

if [ "$HOST_CHECK" = 1 ]; then
    # A check (no code generated, nothing linked); -Zwarnings works on Debian's cargo
    # through RUSTC_BOOTSTRAP=1, as -Zbuild-std does.
    started=$(date +%s)
    /usr/bin/cargo check -p arena-host --target "$TARGET" -Zbuild-std=std,panic_abort --locked \
        -Zwarnings --config 'build.warnings="deny"'
    echo "host check for $TARGET took $(( $(date +%s) - started )) s"
fi

# The Wine shim: exports ProcessPrng, which Wine 8's DLLs lack.
SHIM_DIR="$CARGO_TARGET_DIR/wine"
mkdir -p "$SHIM_DIR"
SHIM="$SHIM_DIR/bcryptprimitives.dll"
if [ ! -f "$SHIM" ] || [ scripts/wine/bcryptprimitives.c -nt "$SHIM" ] || [ scripts/wine/bcryptprimitives.def -nt "$SHIM" ]; then
    x86_64-w64-mingw32-gcc -shared -O2 -o "$SHIM" scripts/wine/bcryptprimitives.c scripts/wine/bcryptprimitives.def -lbcrypt
fi

EXE="$CARGO_TARGET_DIR/$TARGET/$PROFILE/arena-guest.exe"
LAUNCHER="$CARGO_TARGET_DIR/$TARGET/$PROFILE/arena-guest-logon.exe"
RECORDER="$CARGO_TARGET_DIR/$TARGET/$PROFILE/arena-input-recorder.exe"
for f in "$EXE" "$LAUNCHER" "$RECORDER"; do
    if [ ! -f "$f" ]; then
        echo "the build finished but $f is missing" >&2
        exit 1
    fi
done
size=$(stat -c %s "$EXE")
echo "shim: $SHIM"
echo "exe size: $size bytes ($(( size / 1024 )) KiB, $PROFILE, unstripped)"
# What a shipped exe would weigh without its debug information.
if command -v x86_64-w64-mingw32-strip >/dev/null; then
    x86_64-w64-mingw32-strip -o "$CARGO_TARGET_DIR/arena-guest.stripped.exe" "$EXE"
    stripped=$(stat -c %s "$CARGO_TARGET_DIR/arena-guest.stripped.exe")
    echo "exe size stripped: $stripped bytes ($(( stripped / 1024 )) KiB)"
fi
echo "launcher size: $(stat -c %s "$LAUNCHER") bytes ($PROFILE, unstripped)"
if command -v x86_64-w64-mingw32-strip >/dev/null; then
    x86_64-w64-mingw32-strip -o "$CARGO_TARGET_DIR/arena-guest-logon.stripped.exe" "$LAUNCHER"
    stripped=$(stat -c %s "$CARGO_TARGET_DIR/arena-guest-logon.stripped.exe")
    echo "launcher size stripped: $stripped bytes ($(( stripped / 1024 )) KiB)"
fi
echo "exe: $EXE"
echo "launcher: $LAUNCHER"
echo "recorder: $RECORDER"
