"""spadgen.plot: each plot draws what the run holds (image data, one labelled curve per pixel, detection
classes that add up), and `python -m spadgen.plot` writes a PNG for a gate sweep and an intensity run and
fails with a message on a folder that is not a run."""
import subprocess
import sys

import numpy as np
import pytest

matplotlib = pytest.importorskip("matplotlib")
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import spadgen  # noqa: E402
from spadgen import plot  # noqa: E402

PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def sweep(sweep_run):
    return spadgen.open_run(sweep_run)


def test_depth_and_intensity_images(sweep):
    ax = plot.plot_depth(sweep)
    data = ax.images[0].get_array()
    np.testing.assert_array_equal(data.mask, ~sweep.hit())
    np.testing.assert_allclose(data[sweep.hit()], sweep.depth()[sweep.hit()])
    ax = plot.plot_intensity(sweep)
    np.testing.assert_array_equal(ax.images[0].get_array(), sweep.laser["photons_per_pulse"])
    plt.close("all")


def test_gate_profiles_one_labelled_curve_per_pixel(sweep):
    pixels = [(5, 2), (100, 7), (340, 9)]
    ax = plot.plot_gate_profiles(sweep, pixels)
    assert len(ax.lines) == 2 * len(pixels)  # counts and the dashed expected counts
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels[0].startswith("x=5, y=2 (") and labels[2] == "x=340, y=9 (no surface)"
    np.testing.assert_array_equal(ax.lines[2].get_ydata(), sweep.counts[:, 7, 100])
    np.testing.assert_array_equal(ax.lines[2].get_xdata(), sweep.gate_positions_ns)
    assert ax.get_xlabel() == "gate position (ns)"
    # Default pixels: those of previews/gate_profiles.png.
    ax = plot.plot_gate_profiles(sweep, expected=False)
    assert len(ax.lines) == len(sweep.metadata["preview_profile_pixels"])
    plt.close("all")


def test_gate_profiles_expected_from_the_detection_rates(make_run):
    """A run with the default outputs (counts and detection_rate, no expected_counts.npy): the dashed expected
    counts are N (1 - exp(-lambda)) of the pixel's rates (none were drawn)."""
    run = spadgen.open_run(make_run("flat"))
    assert not run.has("expected_counts.npy") and run.has("detection_rate.npy")
    ax = plot.plot_gate_profiles(run, [(1, 1), (5, 5)])
    assert len(ax.lines) == 4 and ax.get_title() == "gate profiles (dashed: expected)"
    lam = np.asarray(run.detection_rate[:, 5, 5], np.float64)
    np.testing.assert_array_equal(ax.lines[3].get_ydata(), (run.frames_per_k * -np.expm1(-lam)).astype(np.float32))
    np.testing.assert_array_equal(ax.lines[3].get_ydata(), run.expected_counts[:, 5, 5])
    plt.close("all")


def test_detection_and_error_maps(sweep):
    truth = sweep.depth()
    detected = np.isfinite(truth)
    detected[:, :10] = False      # 100 missed
    detected[0, -1] = True        # 1 false detection (nothing there)
    ax = plot.plot_detection_map(sweep, detected)
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    hits = int(sweep.hit().sum())
    n = sweep.width * sweep.height
    assert labels == [f"detected ({hits - 100})", "missed (100)", "false detection (1)", f"no surface ({n - hits - 1})"]
    estimate = np.where(np.isfinite(truth), truth + 0.004, np.nan)
    ax = plot.plot_error_map(sweep, estimate)
    np.testing.assert_allclose(ax.images[0].get_array().compressed(), 4.0, rtol=1e-4)
    assert "rms 4.0 mm" in ax.get_title()
    plt.close("all")


@pytest.mark.parametrize("run_name", ["sweep", "intensity"])
def test_command_line_writes_a_png(make_run, tmp_path, run_name):
    out = tmp_path / f"{run_name}.png"
    run = make_run(run_name)
    before = sorted(p.name for p in run.rglob("*"))
    r = subprocess.run([sys.executable, "-m", "spadgen.plot", str(run), "-o", str(out), "--pixel", "3", "4"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert out.read_bytes()[:8] == PNG and out.stat().st_size > 20000
    assert sorted(p.name for p in run.rglob("*")) == before  # nothing written into the run


def test_command_line_names_what_is_wrong(tmp_path):
    r = subprocess.run([sys.executable, "-m", "spadgen.plot", str(tmp_path)], capture_output=True, text=True)
    assert r.returncode == 1 and "no metadata.json" in r.stderr


def test_overview_maps_reconstructs_nearest_return_where_the_run_has_it(sweep_run, spadgen_bin, tmp_path):
    """With detections_edges.exr in the run folder the detection and error maps are of the multi-return
    detector's nearest return (the single-edge baseline finds the sphere behind the multi-object plate: 142 mm
    rms was drawn beside a run whose own detections were right); without it, of the baseline, so named."""
    import shutil
    run_dir = tmp_path / "run"
    shutil.copytree(sweep_run, run_dir)
    base = plot.overview(spadgen.open_run(run_dir))
    assert any("the single-edge baseline" in a.get_title() for a in base.axes)
    subprocess.run([spadgen_bin, "reconstruct", str(run_dir), "-q"], check=True)
    run = spadgen.open_run(run_dir)
    fig = plot.overview(run)
    error = [a for a in fig.axes if a.get_title().startswith("nearest-surface error of reconstruct's nearest return")]
    assert len(error) == 1
    d = run.detections("edges")
    nearest = np.where(np.isfinite(d.range), d.range, np.inf).min(axis=0)
    expected = np.ma.masked_invalid((np.where(np.isfinite(nearest), nearest, np.nan) - run.depth()) * 1e3)
    np.testing.assert_allclose(error[0].images[0].get_array().compressed(), expected.compressed(), rtol=1e-6)
    plt.close("all")
