#!/usr/bin/env bash
# Lints the GitHub workflow files (.github/workflows/*.yml) with two linters from
# PyPI, installed into a private virtual environment under target/:
#   - check-jsonschema against its bundled GitHub-workflow schema (structure, keys, types);
#   - zizmor, offline (unpinned actions, credentials left in checkouts, injection through
#     expressions, excessive permissions).
# First it lints a workflow it writes with known faults and requires both linters to
# reject it, so a linter that silently passes everything is caught.
#
# Without PyPI (an offline machine) it says SKIPPED and passes, unless
# ARENA_REQUIRE_LINT=1 (CI sets it), which makes that a failure.
set -euo pipefail
cd "$(dirname "$0")/.."

VENV=target/lint-venv
ZIZMOR_VERSION=1.32.0
CHECK_JSONSCHEMA_VERSION=0.39.0

skip_or_fail() {
    if [ "${ARENA_REQUIRE_LINT:-0}" = 1 ]; then
        echo "error: $1" >&2
        exit 1
    fi
    echo "SKIPPED: the workflow lint: $1" >&2
    exit 0
}

if [ ! -x "$VENV/bin/zizmor" ] || [ ! -x "$VENV/bin/check-jsonschema" ]; then
    python3 -m venv "$VENV" >/dev/null 2>&1 || skip_or_fail "python3 -m venv failed (Debian: apt-get install python3-venv)"
    "$VENV/bin/pip" install --quiet --disable-pip-version-check \
        "zizmor==$ZIZMOR_VERSION" "check-jsonschema==$CHECK_JSONSCHEMA_VERSION" \
        || skip_or_fail "installing zizmor and check-jsonschema from PyPI failed"
fi

lint() {
    "$VENV/bin/check-jsonschema" --builtin-schema vendor.github-workflows "$@" \
        && "$VENV/bin/zizmor" --offline --quiet "$@"
}

bad=$(mktemp -d)
trap 'rm -rf "$bad"' EXIT
# Faults both linters know: a key the schema forbids, and an unpinned third-party action.
cat >"$bad/bad.yml" <<'YAML'
on: push
jobs:
  j:
    runs-on: ubuntu-latest
    stepz: []
YAML
cat >"$bad/unpinned.yml" <<'YAML'
on: push
permissions: {}
jobs:
  j:
    runs-on: ubuntu-latest
    steps:
      - uses: some-owner/some-action@main
YAML
if "$VENV/bin/check-jsonschema" --builtin-schema vendor.github-workflows "$bad/bad.yml" >/dev/null 2>&1; then
    echo "error: check-jsonschema accepted a workflow with a misspelt key" >&2
    exit 1
fi
if "$VENV/bin/zizmor" --offline --quiet "$bad/unpinned.yml" >/dev/null 2>&1; then
    echo "error: zizmor accepted an unpinned third-party action" >&2
    exit 1
fi

shopt -s nullglob
files=(.github/workflows/*.yml .github/workflows/*.yaml)
if [ "${#files[@]}" -eq 0 ]; then
    echo "error: no workflow files under .github/workflows" >&2
    exit 1
fi
lint "${files[@]}"
echo "workflow lint passed: ${files[*]}"
