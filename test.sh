#!/usr/bin/env bash
# The one command that runs every test:
#   1. the whole workspace (`cargo test --workspace`): unit, route, end-to-end tests on the stub guest;
#   2. the Windows backend: cross-builds arena-guest.exe and drives it under Wine (scripts/wine-test.sh).
# Step 2 needs Debian packages (installed automatically when run as root; see .ci/run).
# ARENA_SKIP_WINE=1 skips it, saying so.
set -euo pipefail
cd "$(dirname "$0")"

started=$(date +%s)
# The Wine test file is part of the workspace; it only runs for real in step 2,
# which sets up the display, the prefix and the exe for it.
env -u ARENA_REQUIRE_WINE -u ARENA_WINDOWS_EXE cargo test --workspace --locked "$@"
echo "workspace tests took $(( $(date +%s) - started )) s"

if [ "${ARENA_SKIP_WINE:-0}" = 1 ]; then
    echo "SKIPPED: the Wine suite (ARENA_SKIP_WINE=1); the Windows backend was not tested" >&2
    exit 0
fi
started=$(date +%s)
scripts/wine-test.sh
echo "Windows cross build and Wine suite took $(( $(date +%s) - started )) s"
