#!/usr/bin/env python3
"""Scores orientation filters on the BROAD recordings (Laidig, Caruso, Cereatti, Seel,
"BROAD - A Benchmark for Robust Inertial Orientation Estimation", Data 6(7), 2021, CC BY 4.0):
sfs's phone-mode filter (through `examples/ahrs_stream.rs`), x-io's Fusion (PyPI `imufusion`)
and VQF (PyPI `vqf`), all with their default parameters, on the same samples.

Metric (BROAD's own): the error quaternion in the earth frame q_imu * inv(q_opt); total error
2*acos(|w|), inclination (heading-free) error 2*acos(sqrt(w^2 + z^2)), heading error
2*atan(|z/w|); RMS over the movement phase, NaN ground truth skipped.

Usage: benches/broad/run.sh (sets up a virtual environment); or
    python3 broad.py --data DIR --sfs PATH_TO_ahrs_stream [--json OUT]
"""
import argparse
import json
import pathlib
import subprocess
import sys

import numpy as np
import scipy.io as spio


def quatmult(a, b):
    w1, x1, y1, z1 = a.T
    w2, x2, y2, z2 = b.T
    return np.stack([
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    ], axis=1)


def errors(q_est, q_opt, movement):
    q_est = q_est / np.linalg.norm(q_est, axis=1)[:, None]
    q_opt = q_opt / np.linalg.norm(q_opt, axis=1)[:, None]
    inv = q_opt * np.array([1, -1, -1, -1])
    d = quatmult(q_est, inv)
    d = d / np.linalg.norm(d, axis=1)[:, None]
    total = 2 * np.arccos(np.clip(np.abs(d[:, 0]), 0, 1))
    heading = 2 * np.arctan(np.abs(d[:, 3] / d[:, 0]))
    incl = 2 * np.arccos(np.clip(np.sqrt(d[:, 0] ** 2 + d[:, 3] ** 2), 0, 1))
    rms = lambda e: float(np.rad2deg(np.sqrt(np.nanmean(e[movement] ** 2))))
    return dict(total=rms(total), heading=rms(heading), inclination=rms(incl))


def run_sfs(exe, gyr, acc, mag, ts, args=()):
    n = len(gyr)
    rec = np.empty((n, 10), dtype='<f8')
    rec[:, 0] = ts
    rec[0, 0] = 0.0
    rec[:, 1:4] = gyr
    rec[:, 4:7] = acc
    rec[:, 7:10] = mag
    run = subprocess.run([exe, *args], input=rec.tobytes(), capture_output=True, check=True)
    sys.stderr.write(run.stderr.decode())
    out = run.stdout
    return np.frombuffer(out, dtype='<f8').reshape(n, 4)


def run_vqf(gyr, acc, mag, ts):
    import vqf
    out = vqf.offlineVQF(np.ascontiguousarray(gyr), np.ascontiguousarray(acc), np.ascontiguousarray(mag), ts)
    return out['quat9D']


def run_vqf_online(gyr, acc, mag, ts):
    import vqf
    f = vqf.VQF(ts)
    out = f.updateBatch(np.ascontiguousarray(gyr), np.ascontiguousarray(acc), np.ascontiguousarray(mag))
    return out['quat9D']


def run_fusion(gyr, acc, mag, ts):
    import imufusion
    rate = 1.0 / ts
    # The values of x-io's example; set as properties (this version's constructor keywords are
    # not all applied).
    s = imufusion.AhrsSettings()
    s.sample_rate = rate
    s.convention = imufusion.CONVENTION_ENU
    s.gain = 0.5
    s.gyroscope_range = 2000.0
    s.acceleration_rejection = 10.0
    s.magnetic_rejection = 10.0
    s.rejection_timeout = int(5 * rate)
    assert s.convention == imufusion.CONVENTION_ENU and s.gyroscope_range == 2000.0
    ahrs = imufusion.Ahrs()
    ahrs.set_settings(s)
    bs = imufusion.BiasSettings()
    bs.sample_rate = rate
    bias = imufusion.Bias()
    bias.set_settings(bs)
    g = np.rad2deg(gyr)
    a = acc / 9.81
    q = np.empty((len(gyr), 4))
    for i in range(len(gyr)):
        gi = bias.update(g[i])
        ahrs.update(gi, a[i], mag[i])
        q[i] = ahrs.get_quaternion()
    return q


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--data', required=True)
    ap.add_argument('--sfs', required=True)
    ap.add_argument('--json')
    ap.add_argument('--only', help='run only the filters whose names are given, comma-separated')
    args = ap.parse_args()
    files = sorted(pathlib.Path(args.data).glob('*.mat'))
    if not files:
        sys.exit(f'no BROAD .mat files in {args.data}')
    filters = [('sfs', lambda *a: run_sfs(args.sfs, *a)),
               ('sfs smoother', lambda *a: run_sfs(args.sfs, *a, args=('--smooth',))),
               ('VQF (offline)', run_vqf),
               ('VQF (online)', run_vqf_online), ('Fusion', run_fusion)]
    if args.only:
        keep = args.only.split(',')
        filters = [f for f in filters if f[0] in keep]
    results = {}
    for f in files:
        m = spio.loadmat(f, squeeze_me=True)
        ts = 1.0 / float(m['sampling_rate'])
        gyr, acc, mag = (np.asarray(m[k], float) for k in ('imu_gyr', 'imu_acc', 'imu_mag'))
        movement = np.asarray(m['movement'], bool)
        q_opt = np.asarray(m['opt_quat'], float)
        results[f.stem] = {name: errors(run(gyr, acc, mag, ts), q_opt, movement) for name, run in filters}
    names = [n for n, _ in filters]
    print('| trial | ' + ' | '.join(f'{n} total / incl.' for n in names) + ' |')
    print('|---|' + '---|' * len(names))
    for trial, r in results.items():
        print(f'| {trial} | ' + ' | '.join(f"{r[n]['total']:.2f}° / {r[n]['inclination']:.2f}°" for n in names) + ' |')
    if args.json:
        pathlib.Path(args.json).write_text(json.dumps(results, indent=2))


if __name__ == '__main__':
    main()
