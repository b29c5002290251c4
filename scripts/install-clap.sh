#!/usr/bin/env bash
# Build the CLAP plugin and install it as unacorda.clap, stripped, where CLAP hosts look: the
# first directory of CLAP_PATH if it is set, else ~/.clap. Prints where it went and its size.
#   bash scripts/install-clap.sh
#   CLAP_PATH=/usr/lib/clap sudo -E bash scripts/install-clap.sh
set -euo pipefail
cd "$(dirname "$0")/.."
# The plugin alone: the library without the command line's dependencies (no ALSA needed).
cargo build --release --locked -p unacorda-clap
built=target/release/libunacorda_clap.so
dir="${CLAP_PATH:-$HOME/.clap}"
dir="${dir%%:*}"
mkdir -p "$dir"
# --strip-unneeded keeps the dynamic symbol the host looks up (clap_entry).
strip --strip-unneeded -o "$dir/unacorda.clap" "$built"
echo "installed $dir/unacorda.clap ($(du -h "$dir/unacorda.clap" | cut -f1); unstripped $(du -h "$built" | cut -f1))"
