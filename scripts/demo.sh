#!/usr/bin/env bash
# Render the una-corda demo on a fresh machine into ./demo-out: one strike of C2 normal and una
# corda, the paper's Figures 2–6, and the demo MIDI file (a phrase played twice, the second time
# with the soft pedal) on the 88-key piano. Needs a Rust toolchain; installs ALSA's headers
# (libasound2-dev, pkg-config) with apt if they are missing.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/deps.sh
out=demo-out
mkdir -p "$out"
cargo build --release --locked
./target/release/unacorda render --preset c2 --seconds 6 --out "$out/c2_normal.wav"
./target/release/unacorda render --preset c2 --una-corda --seconds 6 --out "$out/c2_una_corda.wav"
./target/release/unacorda figures --preset c2 --out-dir "$out"
./target/release/unacorda render --midi assets/midi/demo.mid --out "$out/demo_phrase.wav"
echo "demo written to $out/"
