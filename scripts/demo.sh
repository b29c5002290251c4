#!/usr/bin/env bash
# Render the una-corda demo on a fresh machine: two WAVs (normal, una corda) and the paper's
# Figures 2–6, into ./demo-out. Needs only a Rust toolchain (rustup's default profile).
set -euo pipefail
cd "$(dirname "$0")/.."
out=demo-out
mkdir -p "$out"
cargo build --release --locked
./target/release/unacorda render --offline --preset c2 --seconds 6 --out "$out/c2_normal.wav"
./target/release/unacorda render --offline --preset c2 --una-corda --seconds 6 --out "$out/c2_una_corda.wav"
./target/release/unacorda figures --preset c2 --out-dir "$out"
echo "demo written to $out/"
