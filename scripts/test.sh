#!/usr/bin/env bash
# The test command: formatting, lints, every test (optimised: physics is slow in debug builds),
# and a build of the benchmarks. CI runs exactly this.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/deps.sh
cargo fmt --check
cargo clippy --release --locked --all-targets -- -D warnings
cargo test --release --locked
cargo bench --locked --no-run
