#!/usr/bin/env bash
# Fuzz every parser that reads outside input, with cargo-fuzz (libFuzzer, nightly): MIDI files
# (smf), live MIDI bytes (live_midi), presets (preset), soundboard assets (asset), keyboard
# files (keyboard), the CLAP plugin's saved state (clap_state).
#   bash scripts/fuzz.sh            10 000 runs per target: the smoke run CI does
#   bash scripts/fuzz.sh 1000000    the full run quoted in docs/robustness.md
# The random seed is fixed (FUZZ_SEED, default 1) so that CI is reproducible; set another seed
# to explore elsewhere.
# Each target starts from fuzz/seeds/<target> (committed; crash regressions included) and grows
# fuzz/corpus/<target> (not committed). A crash stops the script with libFuzzer's report and
# leaves the input in fuzz/artifacts/<target>/.
set -euo pipefail
cd "$(dirname "$0")/.."
runs="${1:-10000}"
if ! rustup toolchain list 2>/dev/null | grep -q '^nightly'; then
  echo "fuzz: skipped — cargo-fuzz needs the nightly toolchain (rustup toolchain install nightly)" >&2
  exit 0
fi
command -v cargo-fuzz >/dev/null || cargo install cargo-fuzz --version 0.13.2 --locked
cd fuzz
mkdir -p logs
for t in smf live_midi preset asset keyboard clap_state; do
  mkdir -p "corpus/$t"
  log="logs/$t.log"
  # The plugin's state loader must not blow up on memory either: 64 MB for any one input.
  limit=()
  [ "$t" = clap_state ] && limit=(-malloc_limit_mb=64 -rss_limit_mb=512)
  if ! cargo +nightly fuzz run "$t" "corpus/$t" "seeds/$t" -- -runs="$runs" -max_len=8192 -seed="${FUZZ_SEED:-1}" "${limit[@]}" >"$log" 2>&1; then
    tail -n 60 "$log" >&2
    echo "fuzz: target $t failed (full log: fuzz/$log)" >&2
    exit 1
  fi
  echo "fuzz $t: $(grep -E '^Done' "$log")"
done
