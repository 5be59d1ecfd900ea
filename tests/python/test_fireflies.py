"""Bright outliers of the multi-object scene's laser return at its default 16 paths (docs/render.md, "Guided
connections on the multi-object scene"), on two crops where they were: the plate alone (light that paths
inside the plate carry: Russian roulette on the bare throughput weighted survivors 2.25 times per vertex in
the glass; the plate's ghost of the laser) and the bare sphere beside the plate's edge (the edge's grazing
glint, 0.1 mm wide along it). A pixel counts when it is above 1.5 times the median of its 3 x 3 where the
true image is smooth: the ground truth sees the same object at the nine pixels' centres (no silhouette).

The whole image (bench/fireflies.py, light seeds 1-3) has 0-1 such pixels in 391,268: about 0.13 expected
over these 50,928, so at most 1 allowed is a false alarm of 0.8 % for another seed; the scene's own seed 1
has none. The code before those fixes had 12 and 8 here."""
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
