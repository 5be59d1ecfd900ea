"""Bright outliers of the multi-object scene's laser return at its default 16 paths (docs/render.md, "Guided
connections on the multi-object scene"), on three crops where they were: the plate alone (light that paths
inside the plate carry: Russian roulette on the bare throughput weighted survivors 2.25 times per vertex in
the glass; the plate's ghost of the laser), the bare sphere beside the plate's edge (the edge's grazing
glint, 0.1 mm wide along it) and the plate along that edge (the laser's light piped in through the edge:
none above 1.5 times in 24 light seeds, 3 before its light was aimed at). A pixel counts when it is above
1.5 times the median of its 3 x 3 where the true image is smooth: the ground truth sees the same object at
the nine pixels' centres (no silhouette).

The whole image (bench/fireflies.py, light seeds 1-6) has 0-1 such pixels in 391,266: about 0.07 expected
over these 82,900, so at most 1 allowed per crop is a false alarm under 0.3 % for another seed; the
scene's own seed 1 has none here. The code before those fixes had 12 and 8 on the first two crops, 3 on
the third over 24 light seeds."""
import os
import subprocess

import numpy as np
import pytest

import spadgen


def outliers(run):
    """The pixels above 1.5 times their 3 x 3 median, where no silhouette crosses the 3 x 3 (inner pixels)."""
    img = run.laser["photons_per_pulse"].astype(np.float64)
    ids = run.ground_truth["object_id"]
    H, W = img.shape

    def neighbourhood(a):
        return np.stack([a[i:i + H - 2, j:j + W - 2] for i in range(3) for j in range(3)])

    med = np.median(neighbourhood(img), axis=0)
    n_ids = neighbourhood(ids)
    smooth = (n_ids.max(axis=0) == n_ids.min(axis=0)) & (med > 0)
    ratio = np.where(med > 0, img[1:-1, 1:-1] / np.where(med > 0, med, 1.0), 0.0)
    return int((smooth & (ratio > 1.5)).sum()), int(smooth.sum()), float(ratio[smooth].max())


@pytest.mark.parametrize("name", ["plate_alone", "edge_glint"])
def test_crop_is_smooth(make_run, name):
    run = spadgen.open_run(make_run(name))
    assert run.metadata["accuracy"]["samples_per_pixel"]["min"] == 16  # the scene's default
    bad, smooth, worst = outliers(run)
    assert smooth > 0.9 * (run.width - 2) * (run.height - 2)  # the crop is mostly smooth
    assert bad <= 1, f"{bad} of {smooth} smooth pixels above 1.5 x their 3 x 3 median (worst {worst:.2f})"


def test_plate_along_its_lit_edge_is_smooth(spadgen_bin, tmp_path):
    """The plate along its lit edge (64 x 500 pixels from column 432), light seeds 1, 2 and 6 (three, for the
    sanitizers' time): no pixel above 1.5 times. The code before the edge's light was aimed at had one at
    seed 6 (1.51 times; 3 in 24 seeds, at most 2.39 times), connecting the light without aiming at it one at
    seed 2 (2.62 times; 5 in 24); this code none in 24 seeds (measured on the whole-image reference's smooth
    pixels, bench/fireflies.py's rule). A change of the random sequences alone may fail it: 0 in 24 bounds
    the chance of one outlier per seed below 12 % (95 %)."""
    scene = os.path.join(os.path.dirname(__file__), "..", "..", "scenes", "paper", "multi_object.json")
    for seed in (1, 2, 6):
        out = tmp_path / f"seed{seed}"
        subprocess.run([spadgen_bin, "run", scene, "-q", "-o", str(out), "--set", "camera.crop=[432,0,64,500]",
                        "--set", "acquisition.gate_sweep.step_ps=3600", "--set", "outputs.previews=false",
                        "--set", f"seeds.light={seed}"], check=True)
        bad, smooth, worst = outliers(spadgen.open_run(str(out)))
        assert smooth > 0.9 * 62 * 498
        assert bad == 0, f"light seed {seed}: {bad} of {smooth} smooth pixels above 1.5 x their 3 x 3 median (worst {worst:.2f})"


def test_sphere_beside_the_edge_off_the_lasers_plane_is_smooth(spadgen_bin, tmp_path):
    """The sphere beside the plate's edge, above the laser's height (64 x 64 pixels from (512, 32)), light
    seed 8: no pixel above 1.5 times. There the edge's point nearest the mirror point of the laser sees the
    half-vector tilted about 29 degrees along the edge, while a few centimetres along it and 2 mm across it
    the tilt is one degree: a glint of the lobe's tail, seen and lit at grazing incidence. Aimed at only
    where the nearest point's tilt was under 25 degrees, it made a pixel of 59 times its median here (one
    of the sphere's vertices drew the edge with its diffuse lobe); aimed at wherever the sliver's point of
    least tilt is under 25 degrees, none (1.09 times at most). A change of the random sequences alone may
    pass it without the aim: it guards this realisation."""
    scene = os.path.join(os.path.dirname(__file__), "..", "..", "scenes", "paper", "multi_object.json")
    out = tmp_path / "seed8"
    subprocess.run([spadgen_bin, "run", scene, "-q", "-o", str(out), "--set", "camera.crop=[512,32,64,64]",
                    "--set", "acquisition.gate_sweep.step_ps=3600", "--set", "outputs.previews=false",
                    "--set", "seeds.light=8"], check=True)
    bad, smooth, worst = outliers(spadgen.open_run(str(out)))
    assert smooth > 0.9 * 62 * 62
    assert bad == 0, f"{bad} of {smooth} smooth pixels above 1.5 x their 3 x 3 median (worst {worst:.2f})"
