#!/usr/bin/env bash
# Behaviour unchanged, sample for sample: render a fixed set of sounds and compare their SHA-256
# with the sums recorded in tests/data/same-sound.sha256 (a refactoring must leave every sample as
# it was). The set: c2 normal and una corda on both integrators (4 s), keys A0, C4 and C7 (RK4,
# 4 s, mono) and C4 in stereo, and the demo MIDI file on both integrators (mono) and in stereo.
#   bash scripts/same-sound.sh          render and compare (exit 1 and name the files that differ)
#   bash scripts/same-sound.sh record   render and record the sums (after an intended change)
# The sums hold for one build on one kind of CPU (the AVX2 + FMA path here): floating point is
# deterministic for a given binary and instruction set, not across them.
set -euo pipefail
cd "$(dirname "$0")/.."
sums=tests/data/same-sound.sha256
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
cargo build --release --locked --bin unacorda
bin=./target/release/unacorda
render() { "$bin" render "$@" >/dev/null 2>&1; }
for integrator in rk4 exact; do
  render --preset c2 --seconds 4 --integrator "$integrator" --out "$out/c2_normal_$integrator.wav"
  render --preset c2 --una-corda --seconds 4 --integrator "$integrator" --out "$out/c2_una_corda_$integrator.wav"
  render --midi assets/midi/demo.mid --mono --integrator "$integrator" --out "$out/demo_$integrator.wav"
done
render --midi assets/midi/demo.mid --out "$out/demo_exact_stereo.wav"
for key in A0 C4 C7; do
  render --key "$key" --mono --seconds 4 --out "$out/key_$key.wav"
done
render --key C4 --seconds 4 --out "$out/key_C4_stereo.wav"
(cd "$out" && sha256sum -- *.wav) >"$out/sums"
if [ "${1:-check}" = record ]; then
  cp "$out/sums" "$sums"
  echo "recorded $(wc -l <"$sums") sums in $sums"
  exit 0
fi
if diff -u "$sums" "$out/sums"; then
  echo "same sound: all $(wc -l <"$sums") renders are byte-identical to the recorded ones"
else
  echo "same sound: the renders above differ from $sums" >&2
  exit 1
fi
