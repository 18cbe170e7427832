#!/usr/bin/env bash
# The one command that runs every test:
#   1. formatting (`cargo fmt --check`), lints (`cargo clippy -D warnings`, every target),
#      a host built without the embedded guest (`--no-default-features`), and the GitHub
#      workflow files (scripts/lint-workflows.sh: linters from PyPI);
#   2. the whole workspace (`cargo test --workspace`): unit, route, end-to-end and tidy
#      tests on the stub guest; tests that need the upstream WAA corpus find it through
#      ARENA_WAA_TASKS or ../shared/reference/waa-tasks, and say SKIPPED when it is
#      absent (counted at the end; ARENA_REQUIRE_CORPUS=1 makes that a failure);
#   3. the Windows backend: cross-builds arena-guest.exe and drives it under Wine
#      (scripts/wine-test.sh).
# Step 3 needs Debian packages (installed automatically when run as root; see .ci/run).
# ARENA_SKIP_WINE=1 skips it, saying so.
set -euo pipefail
cd "$(dirname "$0")"

started=$(date +%s)
cargo fmt --all --check
cargo clippy --workspace --all-targets --locked -- -D warnings
cargo clippy -p arena-host --no-default-features --locked -- -D warnings
scripts/lint-workflows.sh
echo "format and lint checks took $(( $(date +%s) - started )) s"

started=$(date +%s)
mkdir -p target
# The stand-in guest image the VM tests boot under QEMU (docs/vm-standin.md):
# the Linux guest binary in an initramfs beside a kernel from Debian's packages.
# Without its tools the VM tests skip loudly (a failure with ARENA_REQUIRE_QEMU=1).
# One build of every test and binary, with the features `cargo test --workspace`
# resolves: the stand-in image embeds this arena-guest, and the suites' own
# `workspace_binary` (tests/support) finds both binaries fresh. A narrower build
# here (`cargo build -p arena-guest`) resolves other features and rebuilds.
cargo test --workspace --locked --no-run
if scripts/build-standin-image.sh >target/standin-build.log 2>&1; then
    tail -1 target/standin-build.log
else
    echo "the stand-in VM image was not built (target/standin-build.log):" >&2
    tail -3 target/standin-build.log >&2
    if [ "${ARENA_REQUIRE_QEMU:-0}" = 1 ]; then
        exit 1
    fi
fi
log=target/test-output.log
# The Wine test file is part of the workspace; it only runs for real in step 3,
# which sets up the display, the prefix and the exe for it.
env -u ARENA_REQUIRE_WINE -u ARENA_WINDOWS_EXE cargo test --workspace --locked "$@" 2>&1 | tee "$log"
echo "workspace tests took $(( $(date +%s) - started )) s; target/ holds $(du -sh target 2>/dev/null | cut -f1)"

# Counts and names the tests whose skip line ends in REASON, under LABEL.
# Anywhere on a line: with one test thread libtest prints "test NAME ... " before the
# test runs, so a skip's line can follow it on the same line.
count_skips() {
    local label=$1 reason=$2 names
    mapfile -t names < <(grep -ao "SKIPPED: .*: $reason" "$log" \
        | sed "s/^SKIPPED: \(.*\): $reason\$/\1/" || true)
    echo "$label skipped: ${#names[@]}"
    for name in "${names[@]}"; do
        echo "  $name"
    done
}
count_skips "corpus tests" "WAA corpus not found"
count_skips "VM tests" "QEMU stand-in image not found"
count_skips "Agent S3 tests" "gui-agents not installed"
count_skips "UI-TARS parser tests" "ui-tars not installed"
count_skips "MCP SDK tests" "no Python with the MCP SDK (set ARENA_MCP_PYTHON to one)"
count_skips "gymnasium tests" "gymnasium not installed"
count_skips "Python tests" "python3 not found"
count_skips "OCR tests" "tesseract not found"
count_skips "agent sandbox tests" "bwrap not found"
count_skips "QEMU tool tests" "\(qemu-img not found\|genisoimage not found\|swtpm not found.*\|Debian's ovmf is not installed\|no secure-boot UEFI firmware.*\)"
# No registry serves upstream's checkout, so these skip wherever ARENA_WAA_ROOT is unset.
count_skips "upstream checkout tests" "ARENA_WAA_ROOT names no WindowsAgentArena checkout"
# The live-desktop suite drives a real Windows desktop (the Windows workflow runs it).
count_skips "live-desktop checks" "\(ARENA_LIVE_DESKTOP is not 1.*\|no notepad.exe in.*\|it needs a Windows 11 client image.*\)"
echo "skips of any kind: $(grep -ao 'SKIPPED: ' "$log" | wc -l)"

if [ "${ARENA_SKIP_WINE:-0}" = 1 ]; then
    echo "SKIPPED: the Wine suite (ARENA_SKIP_WINE=1); the Windows backend was not tested" >&2
    exit 0
fi
started=$(date +%s)
scripts/wine-test.sh
echo "Windows cross build and Wine suite took $(( $(date +%s) - started )) s"
