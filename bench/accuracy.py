#!/usr/bin/env python3
"""The renderer's speed/accuracy trade, measured: for each sampling setting (fixed paths per pixel and the
render.quality presets) and each of the other knobs (render.guided_connections, max_bounces, time_bin_ps)
on crops of the shipped scenes, its wall time and its error against an independent
reference render (another light seed, many more paths), in the units users care about:

- the laser return (laser.exr): |error| / reference, median and p90 over the lit pixels, and what the run
  itself reports (its standard errors, relative, median and p90);
- the expected counts (N (1 - exp(-lambda)) from detection_rate.npy): p99 of |error| in counts, and the
  fraction of (gate position, pixel) samples of at least one expected count whose error exceeds half the
  counts' own shot noise sqrt(E (1 - E / N)) (where the Monte Carlo error starts to matter against the
  sensor's noise);
- depth: `spadgen evaluate --noise-free` (edges detector on the expected counts): recall and range error
  rms in mm against the ground truth, next to the reference's.

Then the sensor model's own knobs (sensor.gate.knots_per_edge, sensor.gate.grid_ps), which do not touch the
light: one render of a wide crop of the multi-object scene with `outputs.light`, then `spadgen sense` of it
per setting, against a sense with 1024 knots (the same light, so the error is the knob's alone): the
sense's wall time and its gate-response stage, the expected counts' error in counts, the detection rate's
largest relative error, and depth as above.

    python3 bench/accuracy.py [--spadgen build/app/spadgen] [--work DIR] [--quick] [--sensor-only] [--markdown FILE]

Writes one table per scene to stdout (Markdown) and, with --markdown, to FILE.
"""
import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, os.path.join(ROOT, "python"))
import spadgen  # noqa: E402

SCENES = {
    # The plate over the sphere's edge: glossy plate reflections, the sphere behind the plate.
    "multi_object": ("scenes/paper/multi_object.json", [448, 200, 128, 64]),
    # A Lambertian wall: direct light only.
    "flat_target": ("scenes/paper/flat_target.json", [448, 218, 128, 64]),
}
SETTINGS = [
    ("4 paths", ["render.samples_per_pixel=4"]),
    ("16 paths (the scenes' default)", ["render.samples_per_pixel=16"]),
    ("64 paths", ["render.samples_per_pixel=64"]),
    ("256 paths", ["render.samples_per_pixel=256"]),
    ("quality=draft", ["render.quality=draft"]),
    ("quality=standard", ["render.quality=standard"]),
    ("quality=reference", ["render.quality=reference"]),
    # The other knobs, each against the 256-path row (paths enough that the knob, not the noise, shows).
    ("guided_connections=false, 16 paths", ["render.samples_per_pixel=16", "render.guided_connections=false"]),
    ("max_bounces=1 (direct light), 256 paths", ["render.samples_per_pixel=256", "render.max_bounces=1"]),
    ("max_bounces=2, 256 paths", ["render.samples_per_pixel=256", "render.max_bounces=2"]),
    ("max_bounces=4, 256 paths", ["render.samples_per_pixel=256", "render.max_bounces=4"]),
    ("time_bin_ps=4.5, 256 paths", ["render.samples_per_pixel=256", "render.time_bin_ps=4.5"]),
    ("time_bin_ps=18, 256 paths", ["render.samples_per_pixel=256", "render.time_bin_ps=18"]),
    ("time_bin_ps=36, 256 paths", ["render.samples_per_pixel=256", "render.time_bin_ps=36"]),
]
REFERENCE = ["render.samples_per_pixel=2048", "seeds.light=1000"]
# The sensor model's knobs, each a `spadgen sense` of one rendered run; the gate at 1024 knots on the
# default grid (0.265 ps: within 8e-8 of the closed form, docs/sensor.md) is the reference.
SENSOR_SCENE = ("scenes/paper/multi_object.json", [0, 186, 1024, 128])
SENSOR_SETTINGS = [
    ("knots_per_edge=8", ["sensor.gate.knots_per_edge=8"]),
    ("knots_per_edge=16", ["sensor.gate.knots_per_edge=16"]),
    ("knots_per_edge=32", ["sensor.gate.knots_per_edge=32"]),
    ("knots_per_edge=64", ["sensor.gate.knots_per_edge=64"]),
    ("knots_per_edge=128", ["sensor.gate.knots_per_edge=128"]),
    ("knots_per_edge=256 (the default)", []),
    ("grid_ps=4", ["sensor.gate.grid_ps=4"]),
    ("grid_ps=16", ["sensor.gate.grid_ps=16"]),
    ("grid_ps=40", ["sensor.gate.grid_ps=40"]),
]
SENSOR_REFERENCE = ["sensor.gate.knots_per_edge=1024"]


def timed(spadgen_bin, cmd, sets, out):
    """Runs `spadgen CMD ... --set S ...` into out, then `spadgen evaluate --noise-free` of it: its wall time,
    the run and the evaluation's metrics."""
    for s in sets:
        cmd += ["--set", s]
    t0 = time.monotonic()
    subprocess.run([spadgen_bin] + cmd, check=True)
    seconds = time.monotonic() - t0
    subprocess.run([spadgen_bin, "evaluate", out, "--noise-free", "-o", out + "-eval"], check=True,
                   stdout=subprocess.DEVNULL)
    with open(os.path.join(out + "-eval", "metrics.json")) as f:
        metrics = json.load(f)
    return seconds, spadgen.Run(out), metrics


def run(spadgen_bin, scene, crop, sets, out):
    return timed(spadgen_bin, ["run", os.path.join(ROOT, scene), "-q", "-o", out, "--set",
                               f"camera.crop=[{','.join(map(str, crop))}]", "--set", "outputs.previews=false"], sets, out)


def sense(spadgen_bin, run_dir, sets, out):
    return timed(spadgen_bin, ["sense", run_dir, "-q", "-o", out], sets, out)


def stage_seconds(r, prefix):
    return sum(s["seconds"] for s in r.metadata["run"]["stages"] if s["stage"].startswith(prefix))


def sensor_errors(r, ref):
    lam = np.asarray(r.detection_rate, np.float64)
    lam_ref = np.asarray(ref.detection_rate, np.float64)
    n = r.frames_per_k
    e, e_ref = n * -np.expm1(-lam), n * -np.expm1(-lam_ref)
    d = np.abs(e - e_ref)
    counted = e_ref >= 1.0
    shot = np.sqrt(np.maximum(e_ref[counted] * (1 - e_ref[counted] / n), 1e-12))
    return {
        "counts_err_p99": float(np.percentile(d, 99)), "counts_err_max": float(d.max()),
        "rate_rel_max": float(np.max(np.abs(lam[counted] - lam_ref[counted]) / lam_ref[counted])),
        "counts_over_tenth_shot": float(np.mean(d[counted] > 0.1 * shot)),
    }


def sensor_knobs(a, work):
    scene, crop = SENSOR_SCENE
    base = os.path.join(work, "sensor_knobs")
    # A window wider than the default gate needs: a coarse grid widens the gate's support by up to a step.
    render_s, _, _ = run(a.spadgen, scene, crop, ["outputs.light=true", "render.window_start_ns=-3",
                                                  "render.window_stop_ns=22"], os.path.join(base, "light"))
    light = os.path.join(base, "light")
    ref_s, ref, ref_m = sense(a.spadgen, light, SENSOR_REFERENCE, os.path.join(base, "reference"))
    gate = ref.metadata["acquisition"]["gate"]
    text = [f"### The sensor model's knobs (multi_object, {crop[2]} x {crop[3]} pixels at ({crop[0]}, {crop[1]}))\n",
            f"One render ({render_s:.1f} s with its evaluation, `outputs.light`), then `spadgen sense` per setting. "
            f"Reference: {' '.join(SENSOR_REFERENCE)} on the default grid ({gate['grid_ps']:.3f} ps), "
            f"knot error {gate['knot_max_error']:.1e} and grid error {gate['grid_max_error']:.1e} of the open gate, sense {ref_s:.2f} s, setup {stage_seconds(ref, 'setup'):.3f} s, gate response "
            f"{stage_seconds(ref, 'sensor: gate response'):.2f} s; noise-free depth against the ground truth: "
            f"recall {ref_m['objects']['recall'] * 100:.2f} %, range error rms {ref_m['range_error']['rms_mm']:.3f} mm.\n",
            "| setting | knot error / grid error (of the open gate) | sense (s) | setup (s) | gate response and rates (s) | "
            "counts error p99 / max | detection rate, largest relative error | samples over 0.1 of the shot noise | depth recall | "
            "depth rms (mm) |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    for label, sets in (SENSOR_SETTINGS[:1] if a.quick else SENSOR_SETTINGS):
        slug = label.split(" (")[0].replace("=", "_")
        out = os.path.join(base, slug)
        s, r, m = sense(a.spadgen, light, sets, out)
        e = sensor_errors(r, ref)
        g = r.metadata["acquisition"]["gate"]
        text.append(f"| {label} | {g['knot_max_error']:.1e} / {g['grid_max_error']:.1e} | {s:.2f} | {stage_seconds(r, 'setup'):.3f} | "
                    f"{stage_seconds(r, 'sensor: gate response'):.2f} | "
                    f"{e['counts_err_p99']:.4f} / {e['counts_err_max']:.3f} | {e['rate_rel_max'] * 100:.3f} % | "
                    f"{e['counts_over_tenth_shot'] * 100:.3f} % | {m['objects']['recall'] * 100:.2f} % | "
                    f"{m['range_error']['rms_mm']:.3f} |")
        shutil.rmtree(out)  # each sense of the crop writes 0.2 GB
    text.append("")
    return text


def errors(r, ref):
    laser = r.laser["photons_per_pulse"].astype(np.float64)
    laser_ref = ref.laser["photons_per_pulse"].astype(np.float64)
    lit = laser_ref > 0
    rel = np.abs(laser[lit] - laser_ref[lit]) / laser_ref[lit]
    se = r.laser["standard_error"].astype(np.float64)[lit] / np.maximum(laser[lit], 1e-300)
    e = r.expected_counts.astype(np.float64)
    e_ref = ref.expected_counts.astype(np.float64)
    n = r.frames_per_k
    d = np.abs(e - e_ref)
    counted = e_ref >= 1.0  # below one expected count the shot noise is no scale
    shot = np.sqrt(np.maximum(e_ref[counted] * (1 - e_ref[counted] / n), 1e-12))
    return {
        "laser_err_p50": float(np.median(rel)), "laser_err_p90": float(np.percentile(rel, 90)),
        "se_p50": float(np.median(se)), "se_p90": float(np.percentile(se, 90)),
        "counts_err_p99": float(np.percentile(d, 99)),
        "counts_over_half_shot": float(np.mean(d[counted] > 0.5 * shot)),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--spadgen", default=os.path.join(ROOT, "build/app/spadgen"))
    ap.add_argument("--work", default=None)
    ap.add_argument("--quick", action="store_true", help="the first two settings and 256 reference paths (a test)")
    ap.add_argument("--markdown", default=None)
    ap.add_argument("--sensor-only", action="store_true", help="only the sensor model's knobs (their table alone)")
    a = ap.parse_args()
    if not (os.path.isfile(a.spadgen) and os.access(a.spadgen, os.X_OK)):
        ap.error(f"--spadgen {a.spadgen}: no such program (build it, or give its path)")
    work = a.work or tempfile.mkdtemp(prefix="spadgen-accuracy-")
    try:
        measure(a, work)
    finally:
        if not a.work:  # its runs are gigabytes: a folder given with --work is kept, a temporary one is not
            shutil.rmtree(work, ignore_errors=True)


def measure(a, work):
    settings = SETTINGS[:2] if a.quick else SETTINGS
    reference = ["render.samples_per_pixel=256", "seeds.light=1000"] if a.quick else REFERENCE
    text = []
    for name, (scene, crop) in ({} if a.sensor_only else SCENES).items():
        ref_s, ref, ref_m = run(a.spadgen, scene, crop, reference, os.path.join(work, name, "reference"))
        rows = []
        for label, sets in settings:
            slug = label.split(" (")[0].replace(" ", "_").replace("=", "_")
            s, r, m = run(a.spadgen, scene, crop, sets, os.path.join(work, name, slug))
            paths = r.metadata["accuracy"]["samples_per_pixel"]["mean"]
            rows.append((label, s, paths, errors(r, ref), m))
        text.append(f"### {name} ({crop[2]} x {crop[3]} pixels at ({crop[0]}, {crop[1]}))\n")
        ref_se = ref.metadata["accuracy"]["laser_relative_standard_error"]
        text.append(f"Reference: {' '.join(reference)}, {ref_s:.1f} s, its own reported relative standard error "
                    f"p50 {ref_se['median'] * 100:.2f} % / p90 {ref_se['p90'] * 100:.2f} % (part of every error below); "
                    f"noise-free depth against the ground truth: recall {ref_m['objects']['recall'] * 100:.2f} %, "
                    f"range error rms {ref_m['range_error']['rms_mm']:.2f} mm.\n")
        text.append("| setting | time (s) | paths per pixel | laser error p50 / p90 | reported SE p50 / p90 | "
                    "counts error p99 | samples over half the shot noise | depth recall | depth rms (mm) |")
        text.append("|---|---|---|---|---|---|---|---|---|")
        for label, s, paths, e, m in rows:
            text.append(f"| {label} | {s:.2f} | {paths:.1f} | {e['laser_err_p50'] * 100:.2f} % / {e['laser_err_p90'] * 100:.2f} % | "
                        f"{e['se_p50'] * 100:.2f} % / {e['se_p90'] * 100:.2f} % | {e['counts_err_p99']:.3f} | "
                        f"{e['counts_over_half_shot'] * 100:.2f} % | {m['objects']['recall'] * 100:.2f} % | "
                        f"{m['range_error']['rms_mm']:.2f} |")
        text.append("")
    text += sensor_knobs(a, work)
    out = "\n".join(text)
    print(out)
    if a.markdown:
        with open(a.markdown, "w") as f:
            f.write(out + "\n")


if __name__ == "__main__":
    main()
