"""examples/paper/reproduce.py --quick: the paper's figures from the shipped scenes, within the paper's
tolerances (the full run writes docs/paper.md)."""
import json
import os
import subprocess
import sys

import pytest

ROOT = os.environ["SPADGEN_SOURCE_DIR"]


@pytest.fixture(scope="module")
def figures(tmp_path_factory):
    out = tmp_path_factory.mktemp("paper")
    subprocess.run([sys.executable, os.path.join(ROOT, "examples", "paper", "reproduce.py"), "--quick",
                    "--spadgen", os.environ["SPADGEN_BIN"], "--docs", str(out), "--json", str(out / "figures.json")],
                   check=True)
    assert (out / "paper.md").read_text().startswith("# The paper reproduced")
    for png in ("fig7_snr.png", "fig10_profiles.png", "fig11_detections.png"):
        assert (out / "paper" / png).stat().st_size > 1000
    return json.loads((out / "figures.json").read_text())


def test_fig7_snr_and_dynamic_range(figures):
    single, dual = figures["fig7"]["single"], figures["fig7"]["dual"]
    # the shot-noise figures (the paper: 34.2 dB maximum; dynamic range 96.3 and 108.1 dB)
    assert single["theory"][0] == pytest.approx(34.2, abs=0.05)
    assert single["theory"][1] == pytest.approx(96.3, abs=0.05)
    assert dual["theory"][1] == pytest.approx(108.2, abs=0.1)
    # the simulated camera follows them: maximum within 1 dB (7 x 1024 pixels: about 0.1 dB of noise in
    # an SNR estimate, plus the coarse sweep), and about 20 dB where the theory says 20 (the integer counts
    # near saturation hold it up to 1.5 dB higher)
    for mode in (single, dual):
        assert mode["simulated"][0] == pytest.approx(mode["theory"][0], abs=1.0)
        assert 19.0 < mode["snr_at_theory_20db"] < 21.5
    # and the square-root law at low light: 10 photons per image give about 10 dB
    x, snr = single["x"], single["snr"]
    assert snr[min(range(len(x)), key=lambda i: abs(x[i] - 10))] == pytest.approx(10.0, abs=1.0)


def test_fig9_accuracy_and_precision(figures):
    for row in figures["fig9"]:
        for det in ("paper", "edges"):
            assert abs(row[det]["accuracy_mm"]) < 10.0, (row["distance_m"], det)
            assert row[det]["precision_mm"] < 7.8, (row["distance_m"], det)
            assert row[det]["one_return"] >= 0.99


def test_fig10_the_plate_is_almost_transparent(figures):
    # "no significant difference" between the 2D images with and without the plate (Fig. 10b)
    assert 0.85 < figures["fig10_11"]["intensity_ratio_on_covered_sphere"] < 1.15


def test_fig11_detection_rates(figures):
    r = figures["fig10_11"]["rates"]
    # the paper's detector: the plate on the majority of plate pixels, the sphere on the majority of the
    # plate-covered sphere pixels (Fig. 11)
    assert r["paper"]["plate_on_plate_pixels"] > 0.9
    assert r["paper"]["sphere_on_covered_sphere_pixels"] > 0.5
    assert r["edges"]["plate_on_plate_pixels"] > 0.95
    assert r["edges"]["sphere_on_covered_sphere_pixels"] > 0.95
    assert r["edges"]["sphere_on_bare_sphere_pixels"] > 0.95
    assert r["edges"]["plate_false_on_bare_sphere"] < 0.01
