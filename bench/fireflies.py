#!/usr/bin/env python3
"""Bright outliers ("fireflies") and the error of the multi-object scene's laser return, with and without
guided connections (render.guided_connections), against an independent high-path reference.

For each setting: its wall time, the pixels above 1.5 times their 3 x 3 median where the reference is
smooth (within 10 % of its own 3 x 3 median; a lit pixel whose median is 0 counts), the worst such ratio
among pixels of a positive median, and the error against the reference
(relative, median / p90 / p99, and the root mean square over the mean). Then, for the default setting,
what its pixels above 1.5 times hold, from the run's ground truth: the camera ray through the pixel's centre
meets nothing (a silhouette: the coverage noise of the paths' jittered positions), the excess over the
reference is indirect light (`indirect_laser`, a reflection before the vertex that meets the laser), or
other. The figures are in docs/render.md.

    /usr/bin/python3 bench/fireflies.py build/app/spadgen [--crop X,Y,W,H] [--paths 16] [--reference 256]
"""
import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np
from scipy.ndimage import median_filter

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, os.path.join(ROOT, "python"))
import spadgen  # noqa: E402

SCENE = os.path.join(ROOT, "scenes", "paper", "multi_object.json")


def run(spadgen_bin, crop, sets, out):
    cmd = [spadgen_bin, "run", SCENE, "-q", "-o", out, "--set", f"camera.crop=[{crop}]", "--set", "outputs.previews=false"]
    for s in sets:
        cmd += ["--set", s]
    t0 = time.monotonic()
    subprocess.run(cmd, check=True)
    r = spadgen.Run(out)
    return time.monotonic() - t0, r.laser["photons_per_pulse"].astype(np.float64), r.ground_truth


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("spadgen")
    ap.add_argument("--crop", default="0,0,1024,500")
    ap.add_argument("--paths", type=int, default=16)
    ap.add_argument("--reference", type=int, default=256)
    a = ap.parse_args()
    work = tempfile.mkdtemp(prefix="spadgen-fireflies-")
    _, ref, _ = run(a.spadgen, a.crop, [f"render.samples_per_pixel={a.reference}", "seeds.light=1000"],
                 os.path.join(work, "reference"))
    mr = median_filter(ref, 3)
    inner = np.zeros_like(ref, bool)
    inner[1:-1, 1:-1] = True
    smooth = inner & (ref > 0) & (np.abs(ref - mr) <= 0.1 * mr)
    lit = ref > 0
    print(f"reference: {a.reference} paths, seeds.light=1000; crop {a.crop}; {smooth.sum()} smooth pixels")
    print("| setting | time (s) | pixels > 1.5 x median | > 3 x | worst (median > 0) | error p50 / p90 / p99 | rms / mean |")
    print("|---|---|---|---|---|---|---|")
    for name, sets in [("guided_connections=false", ["render.guided_connections=false"]),
                       ("guided_connections=true (default)", ["render.guided_connections=true"])]:
        seconds, img, gt = run(a.spadgen, a.crop, [f"render.samples_per_pixel={a.paths}"] + sets, os.path.join(work, name))
        mi = median_filter(img, 3)
        ratio = np.where(mi > 0, img / np.where(mi > 0, mi, 1), np.where(img > 0, np.inf, 0.0))
        rel = np.abs(img - ref)[lit] / ref[lit]
        rms = np.sqrt(np.mean((img - ref)[lit] ** 2)) / ref[lit].mean()
        worst = ratio[smooth & np.isfinite(ratio)].max()
        print(f"| {name}, {a.paths} paths | {seconds:.1f} | {(smooth & (ratio > 1.5)).sum()} | {(smooth & (ratio > 3)).sum()} | "
              f"{worst:.1f} | {np.median(rel) * 100:.2f} % / {np.percentile(rel, 90) * 100:.2f} % / "
              f"{np.percentile(rel, 99) * 100:.2f} % | {rms:.3f} |")
        bad = smooth & (ratio > 1.5)
    # What the default setting's outliers hold (the last one run).
    silhouette = bad & (gt["object_id"] < 0)
    excess = img - ref
    indirect = bad & ~silhouette & (gt["indirect_laser"].astype(np.float64) >= 0.5 * excess)
    other = bad & ~silhouette & ~indirect
    print()
    print("| pixels > 1.5 x median (default) | count | worst ratio (median > 0) |")
    print("|---|---|---|")
    for name, m in [("silhouette (the centre's ray meets nothing)", silhouette),
                    ("excess carried by indirect light", indirect), ("other", other)]:
        fin = ratio[m & np.isfinite(ratio)]
        print(f"| {name} | {m.sum()} | {fin.max() if fin.size else float('nan'):.1f} |")
    shutil.rmtree(work)


if __name__ == "__main__":
    main()
