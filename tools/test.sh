#!/usr/bin/env bash
# The README's test command: installs what a fresh machine lacks
# (tools/setup.sh), then runs every test of the workspace. Arguments go to
# `cargo test` (e.g. `-p framegen`).
set -euo pipefail
cd "$(dirname "$0")/.."
# shellcheck source=tools/setup.sh
source tools/setup.sh
cargo test --workspace "$@"
