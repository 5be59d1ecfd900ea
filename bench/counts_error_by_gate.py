#!/usr/bin/env python3
"""How well Run.expected_counts_error_bound (one standard error of the expected counts' Monte Carlo error, from
the pixel's whole-return relative errors) describes the actual error gate position by gate position, by how
bright the laser's part of lambda is there: the multi-object scene (16 x 8 at (488, 238), the plate over the
sphere), rendered to render.target_relative_error 0.02 and against a 4096-path reference of another light
seed, at each ambient light level given. Prints, per class of gate positions (the reference's laser part of
lambda as a fraction of the pixel's peak), the rms of error / estimate, the share beyond 3, and the 99th
percentile of |error| in counts and against the counts' own shot noise.

    PYTHONPATH=python python3 bench/counts_error_by_gate.py build/app/spadgen [LUX ...]   # default: 0 100

Figures: docs/render.md, "Accuracy"."""
import os
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "python"))
import spadgen  # noqa: E402

SCENE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "scenes", "paper", "multi_object.json")


def run(program, out, lux, *sets):
    cmd = [program, "run", SCENE, "-o", out, "-q", "--set", "camera.crop=[488,238,16,8]", "--set",
           f"ambient.illuminance_lux={lux}", "--set", "outputs.previews=false"]
    for s in sets:
        cmd += ["--set", s]
    subprocess.run(cmd, check=True)
    return spadgen.open_run(out)


def main():
    program = sys.argv[1]
    levels = sys.argv[2:] or ["0", "100"]
    with tempfile.TemporaryDirectory() as tmp:
        for lux in levels:
            a = run(program, os.path.join(tmp, f"a{lux}"), lux, "render.target_relative_error=0.02", "seeds.light=3")
            r = run(program, os.path.join(tmp, f"r{lux}"), lux, "render.samples_per_pixel=4096", "seeds.light=9")
            n = a.frames_per_k
            la = np.asarray(a.detection_rate, np.float64)
            lr = np.asarray(r.detection_rate, np.float64)
            err = n * (np.expm1(-lr) - np.expm1(-la))
            est = np.asarray(a.expected_counts_error_bound(), np.float64)
            part = lr - lr.min(0)
            frac = part / np.maximum(part.max(0), 1e-30)
            shot = np.sqrt(np.maximum(n * -np.expm1(-lr) * np.exp(-lr), 1e-30))
            for lo, hi in ((0.1, 1.01), (0.01, 0.1), (0.0, 0.01)):
                m = (frac >= lo) & (frac < hi) & (est > 0)
                z = err[m] / est[m]
                print(f"{lux} lux, laser part {lo:g} to {min(hi, 1):g} of the pixel's peak: {m.sum()} pixel-gates, "
                      f"error / estimate rms {np.sqrt(np.mean(z ** 2)):.2f}, beyond 3: {np.mean(abs(z) > 3):.3f}, "
                      f"|error| p99 {np.percentile(abs(err[m]), 99):.3f} counts, {np.percentile(abs(err[m]) / shot[m], 99):.2f} "
                      "of the shot noise")


if __name__ == "__main__":
    main()
