"""A baseline depth estimate from gate profiles, for plots and quick checks (not a reference detector).

The method is the paper's, as tests/app/paper_test.cpp applies it to the flat target: smooth each pixel's
profile by a moving average over 2 h + 1 gate positions, find where it first rises halfway from its floor
to its plateau *in photon terms* (counts saturate as N (1 - exp(-lambda)), so the half point is the count level
N (1 - exp(-(lambda_floor + lambda_plateau) / 2)); the floor is the ambient light's and the dark counts'), and turn that fractional gate index into time: the gate closes on the
return when its end reaches it, at tau + gate delay + the pixel's skew + the pixel's gate length; the
range is c (t - laser emission delay) / 2. It finds the nearest surface's rising edge only, ignores range
wrap-around and assumes the laser sits at the camera.
"""
from __future__ import annotations

import warnings

import numpy as np

from .run import C

__all__ = ["smooth_profiles", "half_rise_index", "rising_edge_range"]


def smooth_profiles(p, h=2):
    """Moving average over 2 h + 1 positions along axis 0, averaging only the positions inside the array."""
    p = np.asarray(p, np.float64)
    if h <= 0:
        return p
    pad = np.concatenate([np.zeros((1,) + p.shape[1:]), np.cumsum(p, axis=0)])
    k = np.arange(p.shape[0])
    lo, hi = np.clip(k - h, 0, p.shape[0]), np.clip(k + h + 1, 0, p.shape[0])
    n = (hi - lo).reshape((-1,) + (1,) * (p.ndim - 1))
    return (pad[hi] - pad[lo]) / n


def half_rise_index(p, frames):
    """Fractional index along axis 0 where each profile first rises through the photon midpoint of its floor
    and its plateau; NaN where it never does. ``p`` (K, ...) smoothed counts; ``frames`` the frames summed per
    position."""
    p = np.asarray(p, np.float64)
    top, low = p.max(axis=0), p.min(axis=0)
    # The floor and the plateau: the medians of the positions below and above the middle of the profile's
    # range. (The mean of those within 10 % of the noisy top selects the high ones: the half level sat too
    # high and the range 6.4 mm too far on the counts of a plane at 1 m, against -0.4 mm on its expected
    # counts. Half the top, from zero, is below the floor of a profile under ambient light: a plane at 0.4 m
    # was 3.4 mm near at 100 lux and never found at 300 lux.)
    middle = 0.5 * (top + low)
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # (an all-NaN slice: a flat profile)
        plateau = np.nan_to_num(np.nanmedian(np.where(p >= middle, p, np.nan), axis=0)) if p.size else top
        floor = np.nan_to_num(np.nanmedian(np.where(p < middle, p, np.nan), axis=0)) if p.size else low
    plateau = np.minimum(plateau, frames - 0.5)
    floor = np.minimum(floor, plateau)
    # the midpoint in photons: the mean of the two rates lambda = -log(1 - counts / N), as counts
    half = frames * -np.expm1(0.5 * (np.log1p(-plateau / frames) + np.log1p(-floor / frames)))
    crossing = (p[1:] >= half) & (p[:-1] < half)
    found = crossing.any(axis=0)
    k = np.argmax(crossing, axis=0)
    lo = np.take_along_axis(p, k[None], 0)[0]
    hi = np.take_along_axis(p, (k + 1)[None], 0)[0]
    with np.errstate(invalid="ignore", divide="ignore"):
        idx = k + (half - lo) / (hi - lo)
    return np.where(found & (top > low), idx, np.nan)


def rising_edge_range(run, expected=False, smooth=2, min_signal_sigma=5.0):
    """(H, W) float64 range in metres of the nearest surface, from each pixel's gate profile (counts, or
    expected counts with expected=True); NaN where no edge stands ``min_signal_sigma`` Poisson standard
    deviations above the profile's floor. Gate-sweep runs only."""
    if run.mode != "gate_sweep":
        raise ValueError(f"{run.path}: depth from gate profiles needs a gate_sweep run, this is {run.mode}")
    stack = run.expected_counts if expected else run.counts
    frames = run.frames_per_k
    idx = np.empty((run.height, run.width))
    for y0 in range(0, run.height, 32):  # bands of rows: a megapixel sweep in float64 would take gigabytes
        p = smooth_profiles(np.asarray(stack[:, y0:y0 + 32], np.float64), smooth)
        band = half_rise_index(p, frames)
        top, floor = p.max(axis=0), p.min(axis=0)
        idx[y0:y0 + 32] = np.where(top - floor >= min_signal_sigma * np.sqrt(floor + 1.0), band, np.nan)
    gates = run.gate_positions_ns
    tau = np.interp(idx, np.arange(len(gates)), gates, left=np.nan, right=np.nan)
    scene = run.metadata["resolved_scene"]
    maps = run.sensor_maps
    t_ns = tau + scene["sensor"]["gate"]["delay_ns"] + (maps["gate_skew_ps"] + maps["gate_length_ps"]) / 1000.0
    return (t_ns - scene["laser"]["emission_delay_ns"]) * 1e-9 * C / 2.0
