#!/usr/bin/env bash
# Play the installed VST3 plugin in a real Ardour session with no sound card and no display:
# Ardour's own scanner indexes ~/.vst3/unacorda.vst3, then ardour7-lua (Debian's Ardour 7) makes a
# session on the dummy backend with a MIDI track whose instrument is unacorda, a Lua processor
# before it playing a chord under the sustain pedal (CC64, which reaches the plugin through its
# MIDI mapping as the sustain parameter), and reads the track's meter for 4 s. Fails unless both
# channels sound within 0.75 s of the chord at 0.5 s and peak between -40 and 0 dBFS, the pedal
# holds the released keys (1.5-2 s within 25 dB of the peak) and the dampers take them 40 dB
# under it once the pedal lifts (3.5-4 s). Not in CI: it needs Debian's ardour and ~10 s.
#   bash scripts/install-plugins.sh && bash scripts/ardour/play.sh
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
bundle="$HOME/.vst3/unacorda.vst3"
[ -d "$bundle" ] || { echo "no plugin at $bundle (bash scripts/install-plugins.sh installs it)"; exit 2; }
lib=/usr/lib/ardour7
[ -x "$lib/ardour-vst3-scanner" ] || { echo "no Ardour 7 (apt-get install ardour)"; exit 2; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# Ardour's configuration (where it finds Lua processors) and plugin cache kept in $work.
export XDG_CONFIG_HOME="$work/config" XDG_CACHE_HOME="$work/cache"
mkdir -p "$XDG_CONFIG_HOME/ardour7/scripts"
cp "$here/notes.lua" "$XDG_CONFIG_HOME/ardour7/scripts/unacorda_notes.lua"
LD_LIBRARY_PATH=$lib "$lib/ardour-vst3-scanner" -f "$bundle" > "$work/scan.log" 2>&1 ||
	{ cat "$work/scan.log"; exit 1; }
grep -q "Found Plugin: unacorda" "$work/scan.log" || { cat "$work/scan.log"; exit 1; }
UNACORDA_SESSION="$work/session" timeout 120 ardour7-lua "$here/play.lua" 2>&1 |
	grep -v -e '^$' -e 'Reasonable Synth' -e 'Butler drops' | tee "$work/play.log"
python3 - "$work/play.log" <<'PY'
import re, sys
line = [l for l in open(sys.argv[1]) if l.startswith("summary:")]
if not line:
    sys.exit("no summary: the session did not play")
m = re.search(r"first sound by ([\d.]+) s, peaks (-?[\d.]+) / (-?[\d.]+) dBFS, 1.5-2 s (-?[\d.]+) dBFS, 3.5-4 s (-?[\d.]+)", line[0])
if not m:
    sys.exit("silent: " + line[0].strip())
first, left, right, held, late = map(float, m.groups())
top = max(left, right)
ok = first <= 1.25 and -40 < min(left, right) and top < 0 and held > top - 25 and late < top - 40
print("ardour: " + ("played" if ok else "FAILED") + f": first sound by {first:.2f} s, peaks {left:.1f} / {right:.1f} dBFS, held by the pedal {top - held:.0f} dB under the peak, {top - late:.0f} dB down at 3.5-4 s")
sys.exit(0 if ok else 1)
PY
