#!/usr/bin/env bash
# The one command that runs every test of the workspace.
set -euo pipefail
cd "$(dirname "$0")"
cargo test --workspace --locked "$@"
