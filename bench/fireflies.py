#!/usr/bin/env python3
"""Bright outliers ("fireflies") and the error of the multi-object scene's laser return, with and without
guided connections (render.guided_connections), against an independent high-path reference.

For each setting: its wall time, the pixels above 1.5 times their 3 x 3 median where the reference is
smooth (within 10 % of its own 3 x 3 median, and no silhouette in the 3 x 3: the reference's ground truth
sees the same object at the nine pixels' centres; a lit pixel whose median is 0 counts), and what they hold,
from the run's ground truth: the camera ray through the pixel's centre meets nothing (a silhouette: the
coverage noise of the paths' positions in the pixel), the excess over the reference is indirect light
(`indirect_laser`, a reflection before the vertex that meets the laser), or other; the worst such ratio
among pixels of a positive median, and among the indirect ones; the error against the reference
(relative, median / p90 / p99, and the root mean square over the mean). Each setting for several light
seeds (the counts of rare bright paths vary from one to the next). The figures are in docs/render.md.

    /usr/bin/python3 bench/fireflies.py build/app/spadgen [--crop X,Y,W,H] [--paths 16] [--reference 256] [--seeds 1,2,3]
        [--defaults-only] [--list] [--work DIR]

--work keeps the runs in DIR (default: a temporary folder, removed) and reuses its reference when it holds
one of the same crop and paths, e.g. to compare two builds against one reference.
"""
import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np
from scipy.ndimage import maximum_filter, median_filter, minimum_filter

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
    ap.add_argument("--seeds", type=lambda v: [int(x) for x in v.split(",")], default=[1, 2, 3],
                    help="the light seeds of the runs compared (comma-separated)")
    ap.add_argument("--list", action="store_true", help="print every outlier's pixel")
    ap.add_argument("--defaults-only", action="store_true", help="only the default setting (guided connections on)")
    ap.add_argument("--work", help="keep the runs in this folder and reuse its reference (same crop and paths)")
    a = ap.parse_args()
    work = a.work or tempfile.mkdtemp(prefix="spadgen-fireflies-")
    reference = os.path.join(work, f"reference-{a.reference}-{a.crop.replace(',', '_')}")
    if not os.path.isdir(reference):
        shutil.rmtree(reference + ".partial", ignore_errors=True)
        run(a.spadgen, a.crop, [f"render.samples_per_pixel={a.reference}", "seeds.light=1000"], reference + ".partial")
        os.replace(reference + ".partial", reference)
    r = spadgen.Run(reference)
    ref, ref_gt = r.laser["photons_per_pulse"].astype(np.float64), r.ground_truth
    mr = median_filter(ref, 3)
    inner = np.zeros_like(ref, bool)
    inner[1:-1, 1:-1] = True
    ids = ref_gt["object_id"]
    one_object = maximum_filter(ids, 3) == minimum_filter(ids, 3)
    smooth = inner & (ref > 0) & (np.abs(ref - mr) <= 0.1 * mr) & one_object
    lit = ref > 0
    print(f"reference: {a.reference} paths, seeds.light=1000; crop {a.crop}; {smooth.sum()} smooth pixels")
    print("| setting | light seed | time (s) | pixels > 1.5 x median (silhouette / indirect / other) | > 3 x | "
          "worst (median > 0) | worst indirect | error p50 / p90 / p99 | rms / mean |")
    print("|---|---|---|---|---|---|---|---|---|")
    settings = [("guided_connections=false", ["render.guided_connections=false"]),
                ("guided_connections=true (default)", ["render.guided_connections=true"])]
    for name, sets in settings[1:] if a.defaults_only else settings:
        for seed in a.seeds:
            out = os.path.join(work, f"{name}-{seed}")
            shutil.rmtree(out, ignore_errors=True)
            seconds, img, gt = run(a.spadgen, a.crop, [f"render.samples_per_pixel={a.paths}", f"seeds.light={seed}"] + sets, out)
            mi = median_filter(img, 3)
            ratio = np.where(mi > 0, img / np.where(mi > 0, mi, 1), np.where(img > 0, np.inf, 0.0))
            rel = np.abs(img - ref)[lit] / ref[lit]
            rms = np.sqrt(np.mean((img - ref)[lit] ** 2)) / ref[lit].mean()
            worst = ratio[smooth & np.isfinite(ratio)].max()
            # What the outliers hold, from the run's ground truth.
            bad = smooth & (ratio > 1.5)
            silhouette = bad & (gt["object_id"] < 0)
            indirect = bad & ~silhouette & (gt["indirect_laser"].astype(np.float64) >= 0.5 * (img - ref))
            other = bad & ~silhouette & ~indirect
            fin = ratio[indirect & np.isfinite(ratio)]
            print(f"| {name}, {a.paths} paths | {seed} | {seconds:.1f} | {bad.sum()} ({silhouette.sum()} / {indirect.sum()} / "
                  f"{other.sum()}) | {(smooth & (ratio > 3)).sum()} | {worst:.1f} | {fin.max() if fin.size else 0.0:.1f} | "
                  f"{np.median(rel) * 100:.2f} % / {np.percentile(rel, 90) * 100:.2f} % / "
                  f"{np.percentile(rel, 99) * 100:.2f} % | {rms:.3f} |")
            if a.list:
                for y, x in zip(*np.nonzero(bad)):
                    print(f"    outlier at x {x}, y {y} of the crop: {ratio[y, x]:.2f} x its median, reference "
                          f"{ref[y, x]:.4g}, this run {img[y, x]:.4g}, object {gt['object_id'][y, x]}")
    if not a.work:
        shutil.rmtree(work)


if __name__ == "__main__":
    main()
