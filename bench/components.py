#!/usr/bin/env python3
"""What each component of the model costs: `spadgen run` of the flat target (a crop) with the component on
and off, alternated, and the share of the run's wall time the component takes, (t_on - t_off) / t_on,
the median over the pairs. metadata.json "model" says which components a run uses and why; this measures
what one costs when it is on, and that a component left off costs nothing (the flat target has no
transmissive material, so the refracted connections never run).

    python3 bench/components.py [--spadgen build/app/spadgen] [--pairs 3] [--crop X,Y,W,H]
"""
import argparse
import os
import re
import statistics
import subprocess
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# component: (settings that turn it off, settings that turn it on); the rest as the scene gives it.
COMPONENTS = [
    ("indirect light (render.max_bounces 1 -> 2)", ["render.max_bounces=1"], ["render.max_bounces=2"]),
    ("ambient light (0 -> 1000 lux)", ["ambient.illuminance_lux=0"], ["ambient.illuminance_lux=1000"]),
    ("dark counts (with hot pixels)", ["sensor.dark_counts=false"], ["sensor.dark_counts=true"]),
    ("crosstalk", ["sensor.crosstalk=false"], ["sensor.crosstalk=true"]),
    ("per-pixel gate maps", ["sensor.gate_skew=false"], ["sensor.gate_skew=true"]),
    ("PDP non-uniformity", ["sensor.pdp_nonuniformity=false"], ["sensor.pdp_nonuniformity=true"]),
    ("binary frames (outputs.frames)", ["outputs.frames=false"], ["outputs.frames=true"]),
    ("target error (quality=standard against 32 paths)", ["render.samples_per_pixel=32"], ["render.quality=standard"]),
]


def seconds(spadgen, scene, crop, sets, out):
    cmd = [spadgen, "run", scene, "-q", "-o", out, "--set", f"camera.crop=[{crop}]", "--set", "outputs.previews=false"]
    for s in sets:
        cmd += ["--set", s]
    t0 = time.monotonic()
    subprocess.run(cmd, check=True, stderr=subprocess.DEVNULL)
    return time.monotonic() - t0


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--spadgen", default=os.path.join(ROOT, "build/app/spadgen"))
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--crop", default="384,186,256,128")
    a = ap.parse_args()
    if a.pairs < 1:
        ap.error("--pairs: expected at least 1")
    if not re.fullmatch(r"\d+,\d+,\d+,\d+", a.crop):
        ap.error(f"--crop {a.crop}: expected X,Y,W,H (non-negative integers)")
    if not (os.path.isfile(a.spadgen) and os.access(a.spadgen, os.X_OK)):
        ap.error(f"--spadgen {a.spadgen}: no such program (build it, or give its path)")
    scene = os.path.join(ROOT, "scenes/paper/flat_target.json")
    print(f"flat target, crop [{a.crop}], {a.pairs} alternated pairs, load {os.getloadavg()[0]:.1f}\n")
    print("| component | off (s) | on (s) | share of the run with it on |")
    print("|---|---|---|---|")
    with tempfile.TemporaryDirectory(prefix="spadgen-components-") as work:  # removed however the script ends
        for name, off, on in COMPONENTS:
            t_off, t_on, shares = [], [], []
            for i in range(a.pairs):
                t_off.append(seconds(a.spadgen, scene, a.crop, off, os.path.join(work, f"off{i}")))
                t_on.append(seconds(a.spadgen, scene, a.crop, on, os.path.join(work, f"on{i}")))
                shares.append((t_on[-1] - t_off[-1]) / t_on[-1])
            print(f"| {name} | {statistics.median(t_off):.2f} | {statistics.median(t_on):.2f} | "
                  f"{statistics.median(shares) * 100:.0f} % |")


if __name__ == "__main__":
    main()
