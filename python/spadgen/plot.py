"""Plots of a run with matplotlib: depth and intensity images, gate profiles of chosen pixels, detection and
depth-error maps. Every function draws into a given Axes (or a new figure) and returns the Axes.

    python -m spadgen.plot RUN_DIR [-o FILE.png] [--pixel X Y]...

draws all of them into one figure (default: NAME.png in the current folder, NAME the run folder's name), with
matplotlib's Agg backend, so no display is needed. Nothing is written into the run folder.
"""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np

from .run import open_run

__all__ = ["plot_depth", "plot_intensity", "plot_gate_profiles", "plot_detection_map", "plot_error_map",
           "overview", "main"]


def _axes(ax):
    if ax is not None:
        return ax
    import matplotlib.pyplot as plt
    return plt.figure().add_subplot()


def plot_depth(run, ax=None, kind="range"):
    """The ground-truth depth (metres, viridis: near is bright), misses left blank."""
    ax = _axes(ax)
    d = np.ma.masked_invalid(np.asarray(run.depth(kind), np.float64))
    im = ax.imshow(d, cmap="viridis_r", interpolation="nearest")
    ax.figure.colorbar(im, ax=ax, label=f"{kind} (m)")
    ax.set_title(f"ground-truth {kind}")
    return ax


def plot_intensity(run, ax=None):
    """The image the camera gives: the linearised photon estimate in intensity mode, else the laser light
    reaching each SPAD (photons per pulse, time-integrated)."""
    ax = _axes(ax)
    if run.has("intensity.exr"):
        img, label = run.intensity["photons"], "photons (linearised estimate)"
    else:
        img, label = run.laser["photons_per_pulse"], "laser photons per pulse at the SPAD"
    # As previews/intensity.png: white at the 99.5th percentile, so a few bright outliers do not darken the rest.
    im = ax.imshow(img, cmap="gray", vmin=0, vmax=max(float(np.percentile(img, 99.5)), 1e-30), interpolation="nearest")
    ax.figure.colorbar(im, ax=ax, label=label, extend="max")
    ax.set_title("intensity")
    return ax


def plot_gate_profiles(run, pixels=None, ax=None, expected=True):
    """Counts against gate position (ns) for each pixel (x, y) of ``pixels`` (image coordinates; default: the
    pixels of previews/gate_profiles.png), one colour per pixel, labelled with the pixel and its ground-truth
    range; with expected=True the noise-free expected counts are drawn dashed in the same colour."""
    ax = _axes(ax)
    if pixels is None:
        x0, y0 = run.crop[:2]
        pixels = [(x - x0, y - y0) for x, y in run.metadata["preview_profile_pixels"]]
    depth = run.depth() if run.has("ground_truth.exr") else None
    # expected counts from expected_counts.npy, or N (1 - exp(-lambda)) of detection_rate.npy (gate_profile)
    show_expected = expected and (run.has("expected_counts.npy") or run.has("detection_rate.npy"))
    for i, (x, y) in enumerate(pixels):
        color = f"C{i % 10}"
        p = run.gate_profile(x, y)
        label = f"x={x}, y={y}"
        if depth is not None:
            label += f" ({depth[y, x]:.3f} m)" if np.isfinite(depth[y, x]) else " (no surface)"
        ax.plot(p.gate_ns, p.values, color=color, lw=1.2, label=label)
        if show_expected:
            ax.plot(p.gate_ns, run.gate_profile(x, y, expected=True).values, color=color, lw=0.8, ls="--")
    ax.set_xlabel("gate position (ns)")
    ax.set_ylabel(f"counts (of {run.frames_per_k} frames)")
    ax.set_title("gate profiles" + (" (dashed: expected)" if show_expected else ""))
    ax.legend(fontsize="small")
    ax.grid(alpha=0.3)
    return ax


def plot_detection_map(run, detected=None, ax=None, label="the single-edge baseline"):
    """Where a surface was detected, against the ground truth: detected (a surface is there), missed,
    false detection (no surface), nothing. ``detected`` (H, W) bool, or a depth estimate (finite = detected);
    default: the baseline rising-edge estimate of spadgen.estimate on the sampled counts."""
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch
    ax = _axes(ax)
    if detected is None:
        from .estimate import rising_edge_range
        detected = rising_edge_range(run)
    detected = np.asarray(detected)
    if detected.dtype != bool:
        detected = np.isfinite(detected)
    hit = run.hit()
    cls = np.select([detected & hit, ~detected & hit, detected & ~hit], [0, 1, 2], 3)
    names = ["detected", "missed", "false detection", "no surface"]
    colors = ["#2ca02c", "#d62728", "#ff7f0e", "#202020"]
    ax.imshow(cls, cmap=ListedColormap(colors), vmin=-0.5, vmax=3.5, interpolation="nearest")
    counts = [int((cls == i).sum()) for i in range(4)]
    ax.legend(handles=[Patch(color=c, label=f"{n} ({k})") for c, n, k in zip(colors, names, counts)],
              fontsize="small", loc="upper right", framealpha=0.8)
    ax.set_title(f"detection: {label}")
    return ax


def plot_error_map(run, estimate=None, ax=None, limit_mm=None, label="the single-edge baseline"):
    """A depth estimate (H, W, metres of range; NaN where there is none) minus the ground truth's nearest
    surface, in mm, blue too near, red too far; default estimate: the baseline of spadgen.estimate."""
    ax = _axes(ax)
    if estimate is None:
        from .estimate import rising_edge_range
        estimate = rising_edge_range(run)
    err = (np.asarray(estimate, np.float64) - run.depth()) * 1e3
    err = np.ma.masked_invalid(err)
    if limit_mm is None:
        limit_mm = float(np.percentile(np.abs(err.compressed()), 98)) if err.count() else 1.0
        limit_mm = max(limit_mm, 1e-3)
    im = ax.imshow(err, cmap="coolwarm", vmin=-limit_mm, vmax=limit_mm, interpolation="nearest")
    ax.figure.colorbar(im, ax=ax, label="estimate - ground truth (mm)")
    rms = float(np.sqrt(np.mean(err.compressed() ** 2))) if err.count() else float("nan")
    ax.set_title(f"nearest-surface error of {label}\n(rms {rms:.1f} mm over {err.count()} pixels)")
    return ax


def overview(run, pixels=None):
    """One figure: depth, intensity, gate profiles, and for gate sweeps the detection and error maps: of the
    nearest return ``spadgen reconstruct`` found where the run folder holds its detections_edges.exr (the
    multi-return detector; the baseline finds one edge, the sphere rather than the plate in front of it),
    else of the single-edge baseline (spadgen.estimate.rising_edge_range)."""
    import matplotlib.pyplot as plt
    sweep = run.mode == "gate_sweep" and run.K > 1 and run.has("counts.npy")
    gt = run.has("ground_truth.exr")
    panels = (["depth"] if gt else []) + ["intensity"] + (["profiles"] if sweep else []) + \
             (["detection", "error"] if sweep and gt and run.has("sensor_maps.exr") else [])
    cols = 2 if len(panels) > 1 else 1
    rows = -(-len(panels) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(6.5 * cols, 4.2 * rows), squeeze=False)
    estimate, label = None, "the single-edge baseline"
    if "detection" in panels:
        d = None
        if os.path.isfile(os.path.join(run.path, "detections_edges.exr")):
            try:
                d = run.detections("edges")
            except ValueError:  # another detector's file under that name: the baseline, as without one
                d = None
        if d is not None:
            ranges = np.where(np.isfinite(d.range), d.range, np.inf).min(axis=0)
            estimate, label = np.where(np.isfinite(ranges), ranges, np.nan), "reconstruct's nearest return"
        else:
            from .estimate import rising_edge_range
            estimate = rising_edge_range(run)
    for ax, name in zip(axes.flat, panels):
        {"depth": lambda: plot_depth(run, ax), "intensity": lambda: plot_intensity(run, ax),
         "profiles": lambda: plot_gate_profiles(run, pixels, ax),
         "detection": lambda: plot_detection_map(run, estimate, ax=ax, label=label),
         "error": lambda: plot_error_map(run, estimate, ax=ax, label=label)}[name]()
    for ax in list(axes.flat)[len(panels):]:
        ax.set_axis_off()
    fig.suptitle(f"{os.path.basename(os.path.abspath(run.path))}: {run.width} x {run.height}, {run.mode}, K = {run.K}")
    fig.tight_layout()
    return fig


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m spadgen.plot", description=
                                     "Draws a run's depth, intensity, gate profiles, detection and error maps into one PNG.")
    parser.add_argument("run_dir", help="a folder written by spadgen run")
    parser.add_argument("-o", "--output", help="the PNG to write (default: NAME.png here, NAME the run folder's name)")
    parser.add_argument("--pixel", nargs=2, type=int, action="append", metavar=("X", "Y"),
                        help="a pixel (image coordinates) whose gate profile to draw; repeat for more")
    args = parser.parse_args(argv)
    import matplotlib
    matplotlib.use("Agg")
    try:
        run = open_run(args.run_dir)
        fig = overview(run, [tuple(p) for p in args.pixel] if args.pixel else None)
    except (OSError, KeyError, ValueError, IndexError) as e:
        print(f"spadgen.plot: {e}", file=sys.stderr)
        return 1
    out = args.output or os.path.basename(os.path.abspath(args.run_dir)) + ".png"
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    fig.savefig(out, dpi=100)
    print(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
