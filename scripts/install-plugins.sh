#!/usr/bin/env bash
# Build the plugin library and install it, stripped, in both formats where hosts look:
#   CLAP: unacorda.clap in the first directory of CLAP_PATH if it is set, else ~/.clap;
#   VST3: the bundle unacorda.vst3/Contents/x86_64-linux/unacorda.so in the first directory of
#         VST3_PATH if it is set, else ~/.vst3 (the VST3 SDK's per-user folder on Linux).
# One library serves both (it exports clap_entry and GetPluginFactory). Prints where each went.
#   bash scripts/install-plugins.sh
#   CLAP_PATH=/usr/lib/clap VST3_PATH=/usr/lib/vst3 sudo -E bash scripts/install-plugins.sh
set -euo pipefail
cd "$(dirname "$0")/.."
# The plugin alone: the library without the command line's dependencies (no ALSA needed).
cargo build --release --locked -p unacorda-clap
built=target/release/libunacorda_clap.so
first() { local d="$1"; echo "${d%%:*}"; }
clap_dir=$(first "${CLAP_PATH:-$HOME/.clap}")
vst3_dir=$(first "${VST3_PATH:-$HOME/.vst3}")
bundle="$vst3_dir/unacorda.vst3/Contents/x86_64-linux"
mkdir -p "$clap_dir" "$bundle"
# --strip-unneeded keeps the dynamic symbols hosts look up (clap_entry, GetPluginFactory).
strip --strip-unneeded -o "$clap_dir/unacorda.clap" "$built"
strip --strip-unneeded -o "$bundle/unacorda.so" "$built"
size() { du -h "$1" | cut -f1; }
echo "installed CLAP $clap_dir/unacorda.clap ($(size "$clap_dir/unacorda.clap"); unstripped $(size "$built"))"
echo "installed VST3 $vst3_dir/unacorda.vst3 ($(size "$bundle/unacorda.so"))"
