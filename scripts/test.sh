#!/usr/bin/env bash
# The test command: formatting, lints, every test of the workspace (the library, the command
# line and the CLAP plugin) (optimised: physics is slow in debug builds),
# and a build of the benchmarks. CI runs exactly this.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/deps.sh
cargo fmt --check
cargo clippy --release --locked --workspace --all-targets -- -D warnings
# The library as the plugin builds it: without the command line's dependencies.
cargo clippy --release --locked -p unacorda --no-default-features --lib -- -D warnings
cargo test --release --locked --workspace
cargo bench --locked --workspace --no-run
