#!/usr/bin/env python3
"""Write the test score as a standard MIDI file (format 0, 480 ticks a beat, 120 BPM, channel 1,
velocity 80): the sustain pedal down at 0.9 s, C4 E4 G4 from 1.0 to 2.0 s, the pedal up at 2.5 s,
C5 D5 E5 F5 G5 from 3.0 s (a quarter second each), C3 + C4 from 4.5 to 5.5 s; it ends at 7.0 s.
Usage: score.py OUT.mid"""
import struct
import sys

TPQ = 480
TPS = TPQ * 2  # ticks a second at 120 BPM
events = []  # (tick, order: offs before ons at the same tick, bytes)


def tick(s):
    return int(round(s * TPS))


def note(n, on_s, off_s, velocity=80):
    events.append((tick(on_s), 1, bytes([0x90, n, velocity])))
    events.append((tick(off_s), 0, bytes([0x80, n, 0])))


def cc(number, value, at_s):
    events.append((tick(at_s), 0, bytes([0xB0, number, value])))


def vlq(x):
    out = [x & 0x7F]
    x >>= 7
    while x:
        out.append(0x80 | (x & 0x7F))
        x >>= 7
    return bytes(reversed(out))


cc(64, 127, 0.9)
for n in (60, 64, 67):
    note(n, 1.0, 2.0)
cc(64, 0, 2.5)
for i, n in enumerate((72, 74, 76, 77, 79)):
    note(n, 3.0 + 0.25 * i, 3.0 + 0.25 * (i + 1) - 0.02)
for n in (48, 60):
    note(n, 4.5, 5.5)
events.sort(key=lambda e: (e[0], e[1]))

track = bytearray()
track += vlq(0) + b"\xff\x51\x03" + (500000).to_bytes(3, "big")  # 120 BPM
track += vlq(0) + b"\xff\x58\x04\x04\x02\x18\x08"  # 4/4
last = 0
for t, _, message in events:
    track += vlq(t - last) + message
    last = t
track += vlq(tick(7.0) - last) + b"\xff\x2f\x00"
data = b"MThd" + struct.pack(">IHHH", 6, 0, 1, TPQ) + b"MTrk" + struct.pack(">I", len(track)) + track
with open(sys.argv[1], "wb") as f:
    f.write(data)
