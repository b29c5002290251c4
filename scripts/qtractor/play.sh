#!/usr/bin/env bash
# unacorda in a real DAW, headless: Qtractor opens a session whose MIDI track plays the plugin,
# JACK's dummy backend runs it in real time, and the master bus is recorded and checked
# (levels.py: both channels sound from the first chord on). Not part of CI: it needs Debian's
# qtractor, jackd2, xvfb, jack-capture and libasound2-dev (for the sequencer stand-in below),
# and about 30 s.
#
#   bash scripts/install-plugins.sh && bash scripts/qtractor/play.sh [PLUGIN.clap]
#
# Qtractor will not start its engine without an ALSA sequencer (/dev/snd/seq), which containers
# lack; fakeseq.c, preloaded, answers its sequencer calls as a sequencer with no other client
# would. Qtractor hands a MIDI clip's notes to a track's plugins itself, not through ALSA.
# Exit status 1 if the recording is silent, the first sound is not at the first chord, or the
# plugin panicked.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
plugin=$(realpath "${1:-$HOME/.clap/unacorda.clap}")
work=${UNACORDA_QTRACTOR_DIR:-/tmp/unacorda-qtractor}
[ -f "$plugin" ] || { echo "no plugin at $plugin (bash scripts/install-plugins.sh builds it)"; exit 2; }
for tool in qtractor jackd jack_capture jack_transport jack_lsp Xvfb gcc; do
  command -v "$tool" > /dev/null || { echo "$tool is missing: apt-get install qtractor jackd2 xvfb jack-capture libasound2-dev gcc"; exit 2; }
done
rm -rf "$work" && mkdir -p "$work/xdg/rncbc.org" "$work/run" "$work/clap" && chmod 700 "$work/run"
cd "$work"
cp "$plugin" clap/unacorda.clap
gcc -O1 -shared -fPIC -w -o libfakeseq.so "$here/fakeseq.c" -Wl,--version-script="$here/fakeseq.map"
python3 "$here/score.py" test.mid
sed -e "s#@DIR@#$work#g" -e "s#@PLUGIN@#$work/clap/unacorda.clap#g" "$here/session.qtr" > session.qtr
sed -e "s#@DIR@#$work#g" -e "s#@CLAPDIR@#$work/clap#g" "$here/Qtractor.conf" > xdg/rncbc.org/Qtractor.conf
export XDG_CONFIG_HOME=$work/xdg XDG_RUNTIME_DIR=$work/run DISPLAY=:99
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2> /dev/null || true; done
  sleep 1
  for p in "${pids[@]}"; do kill -9 "$p" 2> /dev/null || true; done
}
trap cleanup EXIT
jackd -d dummy -r 48000 -p 256 > jackd.log 2>&1 &
pids+=($!)
Xvfb :99 -screen 0 1280x1024x24 -nolisten tcp > xvfb.log 2>&1 &
pids+=($!)
for _ in $(seq 50); do jack_lsp > /dev/null 2>&1 && break; sleep 0.2; done
started=$(date +%s.%N)
RUST_BACKTRACE=0 LD_PRELOAD=$work/libfakeseq.so qtractor "$work/session.qtr" > qtractor.log 2>&1 &
qtractor=$!
pids+=($qtractor)
for _ in $(seq 150); do grep -q "Open session" qtractor-messages.log 2> /dev/null && break; sleep 0.2; done
echo "session and plugin loaded in $(python3 -c "import time; print(round(time.time() - $started, 1))") s"
sleep 2
jack_capture -jt -ns -dc -b 24 -p Qtractor:Master/out_1 -p Qtractor:Master/out_2 recording.wav > jack_capture.log 2>&1 &
capture=$!
pids+=($capture)
sleep 1
printf 'locate 0\nplay\n' | jack_transport > /dev/null 2>&1
sleep 9
printf 'stop\n' | jack_transport > /dev/null 2>&1
for _ in $(seq 25); do kill -0 "$capture" 2> /dev/null || break; sleep 0.2; done
kill "$qtractor" 2> /dev/null || true
grep -i "xrun" qtractor-messages.log || true
if grep -q "panicked" qtractor.log; then
  echo "FAILED: the plugin panicked ($(grep -c panicked qtractor.log) times; $work/qtractor.log)"
  exit 1
fi
python3 "$here/levels.py" recording.wav
