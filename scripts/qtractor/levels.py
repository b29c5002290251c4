#!/usr/bin/env python3
"""The levels of a recorded WAV (integer PCM) per channel and per half second, and whether it
sounds as the score (score.py) was played: exit status 1 when a channel is silent or its first
sound is not within 50 ms of the first chord (1.0 s after the transport started).
Usage: levels.py REC.wav"""
import math
import struct
import sys
import wave

FIRST_NOTE_S = 1.0
WINDOW_S = 0.5

w = wave.open(sys.argv[1])
rate, channels, width, frames = w.getframerate(), w.getnchannels(), w.getsampwidth(), w.getnframes()
raw = w.readframes(frames)
w.close()
full = float(1 << (8 * width - 1))
if width == 3:
    values = [int.from_bytes(raw[i : i + 3], "little", signed=True) for i in range(0, len(raw), 3)]
else:
    values = struct.unpack("<%d%s" % (len(raw) // width, {1: "b", 2: "h", 4: "i"}[width]), raw)
ch = [[v / full for v in values[c::channels]] for c in range(channels)]


def db(x):
    return 20 * math.log10(x) if x > 0 else -math.inf


print(f"{sys.argv[1]}: {rate} Hz, {channels} channels, {frames / rate:.2f} s")
ok = channels >= 1
for c, s in enumerate(ch):
    peak = max(map(abs, s)) if s else 0.0
    rms = math.sqrt(sum(x * x for x in s) / max(1, len(s)))
    onset = next((i / rate for i, x in enumerate(s) if abs(x) > 1e-3), None)
    print(
        f"  channel {c + 1}: peak {db(peak):.1f} dBFS, rms {db(rms):.1f} dBFS, first sound at "
        + ("never" if onset is None else f"{onset:.3f} s")
    )
    ok &= onset is not None and abs(onset - FIRST_NOTE_S) < 0.05
step = int(WINDOW_S * rate)
print("  window (s)    " + "   ".join(f"ch{c + 1} rms / peak dBFS" for c in range(channels)))
for i in range(0, frames, step):
    cols = []
    for s in ch:
        seg = s[i : i + step]
        cols.append(f"{db(math.sqrt(sum(x * x for x in seg) / len(seg))):7.1f} / {db(max(map(abs, seg))):6.1f}")
    print(f"  {i / rate:5.2f}-{min(frames, i + step) / rate:5.2f}  " + "      ".join(cols))
print("sounds as played" if ok else "FAILED: silent, or the first sound not at the first chord")
sys.exit(0 if ok else 1)
