#!/usr/bin/env bash
# The test command: formatting, lints, every test of the workspace (the library, the command
# line and the CLAP plugin) (optimised: physics is slow in debug builds),
# and a build of the benchmarks. CI runs exactly this.
# The tests run under cargo-nextest where the machine has it: every test binary's tests share
# both cores at once (cargo test runs the binaries one after another, so one long test keeps a
# core idle); 5.6 min against about 10 on two cores. Doc tests are run by cargo test --doc.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/deps.sh
cargo fmt --check
cargo clippy --release --locked --workspace --all-targets -- -D warnings
# The library as the plugin builds it: without the command line's dependencies.
cargo clippy --release --locked -p unacorda --no-default-features --lib -- -D warnings
if command -v cargo-nextest >/dev/null; then
  cargo nextest run --release --locked --workspace --no-fail-fast
  cargo test --release --locked --workspace --doc
else
  cargo test --release --locked --workspace
fi
cargo bench --locked --workspace --no-run
