"""open_run on real runs: every stack and image as docs/outputs.md describes it, checked against what the
C++ side wrote by independent routes (metadata.json's totals, the transients against laser.exr, summed frames
against counts.npy, intensity.exr against counts.npy), and the helpers (profiles, depth, layers, labels,
errors for what a run did not write)."""
import json
import re

import numpy as np
import pytest

import spadgen
from spadgen.estimate import rising_edge_range


@pytest.fixture(scope="module")
def sweep(sweep_run):
    return spadgen.open_run(sweep_run)


@pytest.fixture(scope="module")
def intensity(intensity_run):
    return spadgen.open_run(intensity_run)


def test_metadata_and_shapes(sweep, intensity):
    for run in (sweep, intensity):
        K, H, W = run.K, run.height, run.width
        assert (W, H) == tuple(run.crop[2:])
        assert run.expected_counts.shape == (K, H, W) and run.expected_counts.dtype == np.dtype("<f4")
        assert run.detection_rate.shape == (K, H, W) and run.detection_rate.dtype == np.dtype("<f4")
        assert run.counts.shape == (K, H, W)
        assert run.counts.dtype == np.dtype(run.metadata["counts_dtype"])
        assert run.frames_packed.shape == (K, run.frames_per_k, H, (W + 7) // 8)
        assert run.frames_packed.dtype == np.uint8
        for stack in (run.detection_rate, run.counts, run.frames_packed):
            assert isinstance(stack, np.memmap) and not stack.flags.writeable  # lazily loaded
        assert run.ground_truth["range"].shape == (H, W)
        assert run["counts"] is run.counts
    assert sweep["laser.exr"] is sweep.laser and not intensity.has("laser")  # the 2D run traces no laser
    assert sweep.counts.dtype == np.uint8 and intensity.counts.dtype == np.uint16  # 255 and 2040 frames per k
    assert (sweep.width, sweep.height, sweep.K) == (347, 10, 36)
    assert sweep.crop == (490, 236, 347, 10)
    assert sweep.mode == "gate_sweep" and intensity.mode == "intensity"
    assert sweep.units["length"] == "m"
    assert sweep.spadgen_version == spadgen.__version__
    # every stream's seed defaults to the scene file's seed (docs/scene-file.md, "Seeds")
    assert sweep.seeds == {"light": sweep.seed, "chip": sweep.seed, "noise": sweep.seed}


def test_time_axis_and_gate_positions(sweep, intensity):
    scene = sweep.metadata["resolved_scene"]["acquisition"]["gate_sweep"]
    expected = scene["start_ns"] + np.arange(sweep.K) * scene["step_ps"] / 1000.0
    np.testing.assert_allclose(sweep.gate_positions_ns, expected, rtol=0, atol=1e-9)
    assert sweep.gate_positions_ns[-1] == pytest.approx(scene["stop_ns"])
    axis = sweep.time_axis
    meta = sweep.metadata["time_axis"]
    assert axis.bins == meta["bins"] == sweep.transient.shape[-1]
    assert axis.end_s == pytest.approx(meta["end_ns"] * 1e-9)
    assert axis.bin_centres_s()[0] == pytest.approx(axis.start_s + axis.bin_width_s / 2)
    np.testing.assert_allclose(intensity.exposures_s, np.array(intensity.acquisition["exposures_us"]) * 1e-6)
    with pytest.raises(ValueError, match="no gate positions"):
        intensity.gate_positions_s


def test_frames_unpacked_and_summed_equal_counts(sweep, intensity):
    for run in (sweep, intensity):
        frames = run.frames()
        assert frames.shape == (run.K, run.frames_per_k, run.height, run.width) and frames.dtype == np.uint8
        assert set(np.unique(frames)) <= {0, 1}
        np.testing.assert_array_equal(frames.sum(axis=1, dtype=np.int64), run.counts)
        # The bits beyond W in each row's last byte are zero.
        pad = run.width % 8
        if pad:
            assert not (np.asarray(run.frames_packed[..., -1]) >> pad).any()
        np.testing.assert_array_equal(run.frames(3 % run.K, 5), frames[3 % run.K, 5])
        # past the file, or not an index: said with the sizes (it was NumPy's bare "index 351 is out of bounds")
        with pytest.raises(IndexError, match=rf"frames\(k={run.K}\) is past the {run.K} gate positions \(0 to {run.K - 1}\)"):
            run.frames(run.K)
        with pytest.raises(IndexError, match=rf"frames\(n={run.frames_per_k}\) is past the {run.frames_per_k} frames per position"):
            run.frames(0, run.frames_per_k)
        with pytest.raises(TypeError, match=r"frames\(k='a'\); expected an int, a slice or indices"):
            run.frames("a")
        # indices as NumPy takes them: a list, an array, NumPy's integers
        np.testing.assert_array_equal(run.frames([0, 1 % run.K]), frames[[0, 1 % run.K]])
        np.testing.assert_array_equal(run.frames(np.int64(0), np.arange(2)), frames[0, :2])
    # The bit order matters: NumPy's default (most significant bit first) mirrors groups of 8 pixels.
    wrong = np.unpackbits(np.asarray(sweep.frames_packed), axis=-1)[..., :sweep.width].sum(axis=1)
    assert not np.array_equal(wrong, sweep.counts)


def test_unpack_frames_bit_layout():
    packed = np.array([[0b00000001, 0b10000010]], np.uint8)  # one row of 13 pixels (2 bytes)
    row = spadgen.unpack_frames(packed, 13)[0]
    assert row.tolist() == [1, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0]
    with pytest.raises(ValueError, match="takes 3 bytes, the array's rows have 2"):
        spadgen.unpack_frames(packed, 17)


def test_standard_error_and_the_counts_bound(sweep):
    """laser.exr's standard error against metadata.json's summary (computed by the C++ side), and the counts
    bound against its formula evaluated per element by hand."""
    se = np.asarray(sweep.laser_standard_error, np.float64)
    laser = np.asarray(sweep.laser["photons_per_pulse"], np.float64)
    assert se.shape == laser.shape and (se >= 0).all() and se.max() > 0
    lit = laser > 0
    rel = np.sort(se[lit] / laser[lit])
    acc = sweep.metadata["accuracy"]
    assert acc["laser_relative_standard_error"]["pixels_with_laser"] == lit.sum()
    assert acc["laser_relative_standard_error"]["median"] == pytest.approx(rel[len(rel) // 2], rel=1e-5)
    assert acc["laser_relative_standard_error"]["max"] == pytest.approx(rel[-1], rel=1e-5)
    bound = sweep.expected_counts_error_bound()
    lam = np.asarray(sweep.detection_rate, np.float64)
    assert bound.shape == lam.shape
    k, y, x = np.unravel_index(np.argmax(bound), bound.shape)
    n = sweep.frames_per_k
    by_hand = n * np.exp(-lam[k, y, x]) * lam[k, y, x] * se[y, x] / laser[y, x]
    assert bound[k, y, x] == pytest.approx(by_hand, rel=1e-5) and by_hand > 0
    # Never more than the counts' own range.
    assert (bound <= n).all()


def test_ambient_standard_error_and_the_counts_bound(intensity_run):
    """ambient.exr's standard error against metadata.json's summary, and the counts bound taking the larger of
    the laser's and the ambient light's relative errors (the test chart: ambient light)."""
    run = spadgen.open_run(intensity_run)
    ase = np.asarray(run.ambient_standard_error, np.float64)
    amb = np.asarray(run.ambient["photons_per_second"], np.float64)
    assert ase.shape == amb.shape and (ase >= 0).all() and ase.max() > 0
    lit = amb > 0
    rel = np.sort(ase[lit] / amb[lit])
    acc = run.metadata["accuracy"]["ambient_relative_standard_error"]
    assert acc["pixels_with_ambient"] == lit.sum()
    assert acc["median"] == pytest.approx(rel[len(rel) // 2], rel=1e-5)
    assert acc["max"] == pytest.approx(rel[-1], rel=1e-5)
    # The test chart's 2D run without acquisition.intensity.laser_on traces no laser: no laser.exr (reading it
    # says why), the bound is the ambient light's alone.
    assert not run.has("laser.exr") and run.metadata["accuracy"]["laser_relative_standard_error"] is None
    with pytest.raises(FileNotFoundError, match="laser.exr.*acquisition.intensity.laser_on"):
        run.laser_standard_error
    bound = run.expected_counts_error_bound()
    lam = np.asarray(run.detection_rate, np.float64)
    k, y, x = np.unravel_index(np.argmax(bound), bound.shape)
    by_hand = run.frames_per_k * np.exp(-lam[k, y, x]) * lam[k, y, x] * ase[y, x] / amb[y, x]
    assert bound[k, y, x] == pytest.approx(by_hand, rel=1e-5) and by_hand > 0


def test_laser_image_equals_metadata_totals_and_transients(sweep):
    laser = sweep.laser
    totals = sweep.metadata["laser_photons_per_pulse"]
    assert laser["photons_per_pulse"].sum(dtype=np.float64) == pytest.approx(totals["total_all_pixels"], rel=1e-6)
    assert laser["out_of_window"].sum(dtype=np.float64) == pytest.approx(totals["outside_time_window"], abs=1e-12)
    # transient.npy covers metadata.json's transient crop: summed over time it is the laser image there,
    # less what fell outside the window.
    tx, ty, tw, th = sweep.metadata["transient"]["crop_in_sensor"]
    assert sweep.transient.shape == tuple(sweep.metadata["transient"]["shape"]) == (th, tw, sweep.time_axis.bins)
    x0, y0 = tx - sweep.crop[0], ty - sweep.crop[1]
    window = (slice(y0, y0 + th), slice(x0, x0 + tw))
    in_window = laser["photons_per_pulse"][window] - laser["out_of_window"][window]
    summed = np.asarray(sweep.transient, np.float64).sum(axis=-1)
    assert in_window.max() > 0
    np.testing.assert_allclose(summed, in_window, rtol=1e-5, atol=1e-12)
    indirect = np.asarray(sweep.transient_indirect)
    assert indirect.shape == sweep.transient.shape
    assert (indirect <= np.asarray(sweep.transient) + 1e-12).all() and indirect.sum() > 0


def test_intensity_image_equals_summed_counts(intensity):
    np.testing.assert_array_equal(intensity.intensity["counts"], np.asarray(intensity.counts, np.int64).sum(axis=0))
    assert (intensity.intensity["photons"] >= 0).all()


def test_hdr_inversion_of_a_2d_run(intensity_run, spadgen_bin, tmp_path):
    """A 2D run's reconstruction is its HDR inversion, hdr.exr, which run.hdr() reads; detections() says so
    (it told to run reconstruct --detector, which 2D runs refuse)."""
    import shutil
    import subprocess
    folder = tmp_path / "run"
    shutil.copytree(intensity_run, folder)
    run = spadgen.open_run(folder)
    with pytest.raises(ValueError, match=r"is a 2D run \(intensity\): no gate profiles .* run.hdr\(\) reads"):
        run.detections()
    with pytest.raises(FileNotFoundError, match=f"write it with spadgen reconstruct {folder}"):
        run.hdr()
    # by its file name (run["hdr.exr"]): reconstruct's file, not the run's, its reader named (it was said not to
    # be written by the run, the file being there)
    with pytest.raises(FileNotFoundError, match=re.escape(f"{folder / 'hdr.exr'}: a file of spadgen reconstruct, not of the "
                                                          f"run (metadata.json does not list it): run.hdr() reads it; not "
                                                          f"written yet: spadgen reconstruct {folder} writes it")):
        run["hdr.exr"]
    subprocess.run([spadgen_bin, "reconstruct", str(folder), "-q"], check=True)
    hdr = run.hdr()
    with pytest.raises(FileNotFoundError, match=re.escape(f"{folder / 'hdr.exr'}: a file of spadgen reconstruct, not of the "
                                                          "run (metadata.json does not list it): run.hdr() reads it") + "$"):
        run["hdr.exr"]
    with pytest.raises(FileNotFoundError, match=re.escape("run.detections('paper', noise_free=True) reads it; not written "
                                                          f"yet: spadgen reconstruct {folder} --detector paper --noise-free")):
        run["detections_paper_noise_free.exr"]
    np.testing.assert_allclose(hdr["photons"], run.intensity["photons"], rtol=1e-6)
    # one written elsewhere (reconstruct -o): read from there, checked to be of this run
    subprocess.run([spadgen_bin, "reconstruct", str(folder), "-q", "-o", str(tmp_path / "mine.exr")], check=True)
    np.testing.assert_array_equal(run.hdr(path=tmp_path / "mine.exr")["photons"], hdr["photons"])
    with pytest.raises(FileNotFoundError, match=f"write it with spadgen reconstruct {folder} -o {tmp_path / 'nope.exr'}"):
        run.hdr(path=tmp_path / "nope.exr")
    # An inversion of another crop of the same size (its header's spadgen_source) is refused, as detections are
    # (it was read beside this run's truth without a word).
    path = folder / "hdr.exr"
    data = path.read_bytes()
    source = data.count(b'"crop_in_sensor":[400,300,40,24]')
    assert source == 1
    path.write_bytes(data.replace(b'"crop_in_sensor":[400,300,40,24]', b'"crop_in_sensor":[401,300,40,24]'))
    with pytest.raises(ValueError, match=f"{path}: the HDR inversion is of another crop of the sensor than {folder}'s "
                                         "\\(made from .*: \\[401, 300, 40, 24\\], this run: \\[400, 300, 40, 24\\]\\)"):
        spadgen.open_run(folder).hdr()
    path.write_bytes(data)
    # An inversion of a run of other settings (here 500 lux of ambient light: the scene's files and crop are the
    # same) is refused, as spadgen evaluate refuses such detections; one of another seed is of this run.
    from conftest import RUNS, SCENES
    scene, sets = RUNS["intensity"]
    for name, more in (("lit", ["ambient.illuminance_lux=500"]), ("seeded", ["seed=7"])):
        cmd = [spadgen_bin, "run", str(SCENES / scene), "-o", str(tmp_path / name), "-q"]
        for v in sets + more:
            cmd += ["--set", v]
        subprocess.run(cmd, check=True)
        subprocess.run([spadgen_bin, "reconstruct", str(tmp_path / name), "-q", "-o", str(tmp_path / f"{name}.exr")], check=True)
    with pytest.raises(ValueError, match=f"{tmp_path / 'lit.exr'}: the HDR inversion is of other settings \\(a --set value"):
        run.hdr(path=tmp_path / "lit.exr")
    assert run.hdr(path=tmp_path / "seeded.exr")["photons"].shape == hdr["photons"].shape
    assert spadgen.open_run(tmp_path / "lit").metadata["settings_hash_fnv1a64"] != run.metadata["settings_hash_fnv1a64"]
    # A symbolic link to nothing in its place: named as such, with how to write the file (the remedy was lost).
    path.unlink()
    path.symlink_to(tmp_path / "gone.exr")
    with pytest.raises(FileNotFoundError, match=f"{path}: a symbolic link to {tmp_path / 'gone.exr'}, which does not "
                                                f"exist; write it with spadgen reconstruct {folder}"):
        spadgen.open_run(folder).hdr()


def test_ground_truth_layers_and_labels(sweep):
    gt = sweep.ground_truth
    n = sweep.metadata["ground_truth_layers"]
    assert n == 3  # plate front, plate back, sphere
    assert sorted(c for c in gt if c.startswith("layer") and c != "layer_count") == \
        sorted(f"layer{i}.{q}" for i in range(n) for q in ("range", "transmittance"))
    layers = sweep.layers()
    H, W = sweep.height, sweep.width
    assert layers.count.shape == (H, W) and layers.count.dtype == np.int32
    assert layers.range.shape == layers.transmittance.shape == (n, H, W)
    assert layers.count.max() == n
    exists = np.arange(n)[:, None, None] < layers.count
    np.testing.assert_array_equal(np.isfinite(layers.range), exists)
    assert (layers.range[1:][exists[1:]] > layers.range[:-1][exists[1:]]).all()  # nearest first
    hit = sweep.hit()
    np.testing.assert_array_equal(hit, layers.count > 0)
    np.testing.assert_array_equal(np.where(hit, layers.range[0], np.inf), sweep.depth())
    mesh, material = sweep.labels()
    assert mesh.dtype == np.int32
    np.testing.assert_array_equal(mesh == -1, ~hit)
    # The scene: the plate (mesh 0) left of sensor x = 512 with the sphere behind it; the bare sphere (mesh 1);
    # nothing beyond the sphere's edge (sensor x > 826).
    x = np.arange(W) + sweep.crop[0]
    assert (mesh[:, x < 512] == 0).all() and (layers.count[:, x < 512] == 3).all()
    assert (mesh[:, (x >= 512) & (x < 800)] == 1).all() and (mesh[:, x > 830] == -1).all()
    assert (sweep.depth("z") <= sweep.depth() + 1e-7)[hit].all()
    with pytest.raises(ValueError):
        sweep.depth("distance")


def test_object_slots(sweep, intensity):
    assert [o["name"] for o in sweep.objects] == ["plate", "sphere"]
    assert [o["id"] for o in sweep.objects] == [0, 1]
    J, H, W = sweep.metadata["ground_truth_objects"], sweep.height, sweep.width
    assert J == 2
    o = sweep.object_slots()
    assert o.first.shape == o.count.shape == (H, W) and o.first.dtype == o.count.dtype == np.int32
    for a in (o.id, o.range, o.transmittance, o.laser, o.edge_counts, o.edge_snr, o.detectable):
        assert a.shape == (J, H, W)
    assert o.id.dtype == np.int32 and o.detectable.dtype == bool and o.laser.dtype == np.float32
    used = np.arange(J)[:, None, None] < o.count
    np.testing.assert_array_equal(o.id >= 0, used)
    np.testing.assert_array_equal(np.isfinite(o.range), used)
    np.testing.assert_array_equal(o.first, np.where(sweep.hit(), o.id[0], -1))
    # An object's slot is its first surface: the plate's front face is layer 0.
    layers = sweep.layers()
    np.testing.assert_array_equal(o.range[0][used[0]], layers.range[0][used[0]])
    assert (o.count <= layers.count).all() and (o.count < layers.count).any()  # the plate's two faces
    # What the objects return, with the other objects' direct light and the indirect light, is laser.exr.
    laser = sweep.laser["photons_per_pulse"].astype(np.float64)
    total = o.laser.astype(np.float64).sum(0) + o.direct_other_laser + o.indirect_laser
    np.testing.assert_allclose(total, laser, rtol=1e-5, atol=0)
    # The returns' optical paths: where slot 0 is the plate's front face (nothing before it), the laser
    # (laser.offset_m 3 cm to the right of the camera) to the face and the face to the camera centre.
    cam = sweep.metadata["camera"]
    K, c2w = np.array(cam["intrinsics"]), np.array(cam["camera_to_world"])
    v, u = np.mgrid[0:H, 0:W]
    d = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones((H, W))], -1)
    d = (d / np.linalg.norm(d, axis=-1, keepdims=True)) @ c2w[:3, :3].T
    origin = np.array(cam["position_m"])
    p = origin + d * o.range[0].astype(np.float64)[..., None]
    laser = origin + 0.03 * c2w[:3, 0]
    plate = (o.id[0] == 0) & used[0]
    assert plate.any()
    expected = o.range[0] + np.linalg.norm(p - laser, axis=-1)
    np.testing.assert_allclose(o.path[0][plate], expected[plate], rtol=2e-6)
    assert np.isinf(o.path[~used]).all()
    assert (o.path[1][used[1]] > 2 * o.range[1][used[1]]).all()  # the sphere through the plate: its glass both ways
    # Labels: the same slots; detectable exactly where the edge reaches five standard deviations.
    np.testing.assert_array_equal(sweep.object_labels["object0.id"], o.id[0])
    np.testing.assert_array_equal(o.detectable, o.edge_snr >= 5)
    assert o.detectable.any()
    assert (o.edge_counts[~used] == 0).all()
    # A 2D run has object slots but no labels; without acquisition.intensity.laser_on it traces no laser, so no
    # object's return either.
    two_d = intensity.object_slots()
    assert two_d.edge_snr is None and not intensity.has("labels.exr")
    assert two_d.laser is None and two_d.direct_other_laser is None and two_d.indirect_laser is None
    assert two_d.id.shape == two_d.range.shape and (two_d.count > 0).any()


def test_expected_counts_from_the_detection_rate(sweep, intensity):
    # The sweep wrote both files: the expectation computed from lambda is the C++ side's to float32 rounding.
    assert sweep.has("expected_counts.npy") and not intensity.has("expected_counts.npy")
    N = sweep.frames_per_k
    derived = (N * -np.expm1(-np.asarray(sweep.detection_rate, np.float64)))
    np.testing.assert_allclose(derived, sweep.expected_counts, rtol=2e-6, atol=2e-6 * N)
    # Without the file, Run computes it; summed over the frames, counts scatter around it.
    e = intensity.expected_counts
    assert e.dtype == np.float32 and e.shape == intensity.counts.shape
    assert np.all((e >= 0) & (e <= intensity.frames_per_k))
    assert abs(float(intensity.counts.astype(np.float64).sum() - e.astype(np.float64).sum())) < 5 * np.sqrt(e.sum() + 1)


def test_saved_light_rebuilds_the_transient(sweep):
    # light/ keeps each pixel's transient over its lit bins (docs/outputs.md, section Saved light); inside
    # the transient crop it rebuilds transient.npy exactly.
    lx0, ly0, lw, lh = sweep.metadata["light"]["crop_in_sensor"]
    r, o, v = sweep["light/ranges"], sweep["light/offsets"], sweep["light/values"]
    assert r.shape == (lh, lw, 2) and o.shape == (lh * lw + 1,) and o[-1] == v.size
    tx0, ty0, tw, th = sweep.metadata["transient"]["crop_in_sensor"]
    T = sweep.transient.shape[2]
    for y in range(th):
        for x in range(tw):
            ly, lx = ty0 + y - ly0, tx0 + x - lx0
            i = ly * lw + lx
            g = np.zeros(T, np.float32)
            g[r[ly, lx, 0]:r[ly, lx, 1]] = v[o[i]:o[i + 1]]
            np.testing.assert_array_equal(g, sweep.transient[y, x])


def test_gate_profile(sweep):
    p = sweep.gate_profile(30, 4)
    np.testing.assert_array_equal(p.values, sweep.counts[:, 4, 30])
    np.testing.assert_array_equal(p.gate_ns, sweep.gate_positions_ns)
    e = sweep.gate_profile(30, 4, expected=True)
    np.testing.assert_array_equal(e.values, sweep.expected_counts[:, 4, 30])
    sx, sy = sweep.metadata["preview_profile_pixels"][0]
    q = sweep.gate_profile(sx, sy, sensor_coordinates=True)
    assert (q.x, q.y) == (sx - sweep.crop[0], sy - sweep.crop[1])
    with pytest.raises(IndexError, match=rf"pixel \(x {sweep.width}, y 0\) lies outside the {sweep.width} x"):
        sweep.gate_profile(sweep.width, 0)
    # in sensor coordinates, named as given, with the crop (it named the image coordinates they became)
    c = sweep.crop
    with pytest.raises(IndexError, match=rf"sensor pixel \(x 5, y 7\) lies outside the run's crop, x {c[0]} to {c[0] + c[2] - 1} "):
        sweep.gate_profile(5, 7, sensor_coordinates=True)
    # a pixel is a whole index (2.7 reached NumPy's "only integers, slices ..."); NumPy's integers are whole
    with pytest.raises(TypeError, match=r"gate_profile: x = 2.7; expected a whole pixel index"):
        sweep.gate_profile(2.7, 3)
    with pytest.raises(TypeError, match=r"gate_profile: y = True; expected"):
        sweep.gate_profile(3, True)
    np.testing.assert_array_equal(sweep.gate_profile(np.int64(30), np.int32(4)).values, p.values)


def test_a_damaged_or_other_folder_is_named_with_what_it_is(make_run, tmp_path):
    """Files damaged after a run published them, a run of another version, and folders that are not runs: each
    error names the file or folder and what it is (they were bare JSON, NumPy and KeyError messages)."""
    import shutil
    import subprocess
    run = tmp_path / "run"
    shutil.copytree(make_run("light_only"), run)
    with open(run / "counts.npy", "r+b") as f:
        f.truncate(200)
    with pytest.raises(ValueError, match=f"{run / 'counts.npy'}: not a readable .npy file .*cut short or damaged"):
        spadgen.open_run(run).counts
    (run / "counts.npy").unlink()
    with pytest.raises(FileNotFoundError, match=f"{run / 'counts.npy'}: listed in .*metadata.json \\(files\\) but missing"):
        spadgen.open_run(run).counts
    (run / "laser.exr").unlink()  # an image too (it was a bare "No such file or directory")
    with pytest.raises(FileNotFoundError, match=f"{run / 'laser.exr'}: listed in .*metadata.json \\(files\\) but missing"):
        spadgen.open_run(run).laser
    # metadata.json edited to other types than a run writes: named with the key (bare ValueError, KeyError,
    # TypeError and IndexError from wherever they were read), and a stack of another shape than its (K, H, W)
    good = (run / "metadata.json").read_text()
    for key, value, says in (("image", {"width": "abc", "height": 10}, "image.width is \"abc\", not an integer"),
                             ("files", ["counts.npy", 7], "files holds an entry that is not a file name"),
                             ("camera", {"intrinsics": None}, "camera.intrinsics is not a 3 x 3 matrix"),
                             ("acquisition", "x", "acquisition is not an object")):
        meta = json.loads(good)
        meta[key] = value
        (run / "metadata.json").write_text(json.dumps(meta))
        with pytest.raises(ValueError, match=f"{run / 'metadata.json'}: " + says.replace("(", "\\(")):
            spadgen.open_run(run)
    (run / "metadata.json").write_text(good)
    np.save(run / "counts.npy", np.zeros((2, 3, 4), np.uint8))
    with pytest.raises(ValueError, match="counts.npy: shape \\(2, 3, 4\\), but metadata.json's \\(K, H, W\\) is"):
        spadgen.open_run(run).counts
    (run / "counts.npy").unlink()
    meta = json.loads(good)
    del meta["ground_truth_objects"]
    meta["spadgen_version"] = "0.0.9"
    (run / "metadata.json").write_text(json.dumps(meta))
    with pytest.raises(KeyError, match="has no 'ground_truth_objects': the run was written by spadgen 0.0.9"):
        spadgen.open_run(run).object_slots()
    (run / "metadata.json").write_text('{"files": [')
    with pytest.raises(ValueError, match=f"{run / 'metadata.json'}: not valid JSON .*damaged or cut short"):
        spadgen.open_run(run)
    # numbers JSON does not have, which json.load takes as non-finite floats (intrinsics of 1e999 reached the
    # rays as infinity): refused as the program refuses them
    for number, says in (("1e999", "the number 1e999 is beyond a double"), ("NaN", "NaN is not a JSON number"),
                         ("-Infinity", "-Infinity is not a JSON number")):
        meta = json.loads(good)
        meta["camera"]["intrinsics"][0][0] = 98765.25
        (run / "metadata.json").write_text(json.dumps(meta).replace("98765.25", number))
        with pytest.raises(ValueError, match=f"{run / 'metadata.json'}: not valid JSON \\({says}\\)"):
            spadgen.open_run(run)
    with pytest.raises(FileNotFoundError, match="nothing: no such folder"):
        spadgen.open_run(tmp_path / "nothing")
    (tmp_path / "ds").mkdir()
    (tmp_path / "ds" / "dataset.json").write_text("{}")
    with pytest.raises(FileNotFoundError, match="a dataset folder, not a run folder: spadgen.open_dataset"):
        spadgen.open_run(tmp_path / "ds")
    (tmp_path / "repeats" / "repeat_000").mkdir(parents=True)
    (tmp_path / "repeats" / "repeat_000" / "metadata.json").write_text("{}")
    with pytest.raises(FileNotFoundError, match="holds 1 run folder\\(s\\): repeat_000"):
        spadgen.open_run(tmp_path / "repeats")
    # a dataset's samples/ folder is named as one (it was called sense's realisations)
    (tmp_path / "ds" / "samples" / "000000").mkdir(parents=True)
    (tmp_path / "ds" / "samples" / "000000" / "metadata.json").write_text("{}")
    with pytest.raises(FileNotFoundError, match="holds 1 run folder\\(s\\): 000000 \\(a dataset's samples: spadgen.open_dataset"):
        spadgen.open_run(tmp_path / "ds" / "samples")


def test_metadata_without_what_every_run_writes_is_named(make_run, tmp_path):
    """metadata.json edited: without its image section, time_axis or the dataset section of another type (they
    were a bare KeyError: 'image', "TypeError: string indices must be integers" and an AttributeError), named
    with the file and the key."""
    import shutil
    run = tmp_path / "run"
    shutil.copytree(make_run("light_only"), run)
    meta = run / "metadata.json"
    good = json.loads(meta.read_text())
    meta.write_text(json.dumps({k: v for k, v in good.items() if k != "image"}))
    with pytest.raises(ValueError, match=f"{meta}: has no image.width, which every run writes"):
        spadgen.open_run(run).width
    with pytest.raises(ValueError, match=f"{meta}: has no image.(width|height)"):
        spadgen.open_run(run).depth()
    pytest.importorskip("torch")
    from spadgen.torchdata import RunDataset
    with pytest.raises(ValueError, match=f"{meta}: has no image"):
        RunDataset([run], fields=("counts",))
    for key, value, says in (("time_axis", "x", "time_axis is not an object"),
                             ("time_axis", dict(good["time_axis"], bins="x"), 'time_axis.bins is "x", not an integer'),
                             ("dataset", "x", "dataset is not an object"), ("units", [1], "units is not an object")):
        meta.write_text(json.dumps(dict(good, **{key: value})))
        with pytest.raises(ValueError, match=f"{meta}: {says}"):
            spadgen.open_run(run).time_axis
    meta.write_text(json.dumps({k: v for k, v in good.items() if k != "time_axis"}))
    with pytest.raises(ValueError, match=f"{meta}: has no time_axis.start_ns"):
        spadgen.open_run(run).time_axis
    # what every run writes, absent: named as such (each was a bare KeyError naming the key alone)
    for key, read in (("units", lambda r: r.units), ("objects", lambda r: r.objects), ("seed", lambda r: r.seed),
                      ("spadgen_version", lambda r: r.spadgen_version)):
        meta.write_text(json.dumps({k: v for k, v in good.items() if k != key}))
        with pytest.raises(ValueError, match=f"{meta}: has no {key}, which every run writes"):
            read(spadgen.open_run(run))
    meta.write_text(json.dumps(dict(good, acquisition={k: v for k, v in good["acquisition"].items()
                                                       if k != "gate_positions_ns"})))
    assert good["acquisition"]["mode"] == "gate_sweep"  # (it said "a 2D intensity run has no gate positions")
    with pytest.raises(ValueError, match=f"{meta}: has no acquisition.gate_positions_ns, which every run writes"):
        spadgen.open_run(run).gate_positions_ns
    # what no run writes: a counts dtype the program does not write, a fractional number of time bins, a seed
    # that is not an integer (each was accepted)
    for key, value, says in (("counts_dtype", "int7", 'counts_dtype is "int7", not "uint8" or "uint16"'),
                             ("time_axis", dict(good["time_axis"], bins=2394.5), "time_axis.bins is 2394.5, not an integer"),
                             ("seed", 1.5, "seed is 1.5, not an integer")):
        meta.write_text(json.dumps(dict(good, **{key: value})))
        with pytest.raises(ValueError, match=f"{meta}: {says}"):
            spadgen.open_run(run)
    meta.write_text(json.dumps(good))
    assert spadgen.open_run(run).time_axis.bins == good["time_axis"]["bins"]


def test_counts_above_the_frames_or_of_another_dtype_are_refused(make_run, tmp_path):
    """Counts the run cannot have written (`spadgen reconstruct` refuses them): above N = frames_per_k (N + 1 in
    a uint16 file was read as a count), or of another dtype than metadata.json's counts_dtype (NaN float
    counts were read, also through torchdata). The error names the file, the first bad (k, y, x) and its value."""
    import shutil
    run = tmp_path / "run"
    shutil.copytree(make_run("intensity"), run)
    good = np.load(run / "counts.npy")
    n = spadgen.open_run(run).frames_per_k
    assert good.dtype == np.uint16 and good.max() <= n and good.shape[0] >= 2
    bad = good.copy()
    bad[1, 5, 7] = n + 7
    bad[1, 2, 3] = n + 1
    np.save(run / "counts.npy", bad)
    says = f"{run / 'counts.npy'}: the count at \\(k, y, x\\) = \\(1, 2, 3\\) is {n + 1}, more than metadata.json's " \
           f"acquisition.frames_per_k = {n}"
    with pytest.raises(ValueError, match=says):
        spadgen.open_run(run).counts
    with pytest.raises(ValueError, match=says):
        spadgen.open_run(run).gate_profile(0, 0)
    pytest.importorskip("torch")
    from spadgen.torchdata import RunDataset
    with pytest.raises(ValueError, match=says):
        RunDataset([run], fields=("counts",))[0]
    np.save(run / "counts.npy", np.full(good.shape, np.nan, np.float32))
    with pytest.raises(ValueError, match=f"{run / 'counts.npy'}: dtype <f4, but the run writes counts as uint16"):
        RunDataset([run], fields=("counts",))[0]
    np.save(run / "counts.npy", good)
    assert np.array_equal(spadgen.open_run(run).counts, good)


def test_images_of_another_run_are_refused(make_run, tmp_path):
    """An EXR image of another run copied into the folder: of another size (depth (48, 64) beside 10 x 10
    counts, object slots of two shapes, a broadcast error in torchdata), or of the same size but another crop
    (its header's spadgen_crop): refused naming the file, what it holds and what the run expects. A folder in
    place of an image is named as such (Run.detections said "no such file")."""
    import shutil
    run = tmp_path / "run"
    shutil.copytree(make_run("light_only"), run)
    gt = run / "ground_truth.exr"
    shutil.copy(make_run("posed") / "ground_truth.exr", gt)
    says = f"{gt}: a 64 x 48 image, but metadata.json's image is 10 x 10: the file is not this run's"
    with pytest.raises(ValueError, match=says):
        spadgen.open_run(run).depth()
    with pytest.raises(ValueError, match=says):
        spadgen.open_run(run).object_slots()
    pytest.importorskip("torch")
    from spadgen.torchdata import RunDataset
    with pytest.raises(ValueError, match=says):
        RunDataset([run], fields=("layer_depth",))[0]
    shutil.copy(make_run("light_only") / "ground_truth.exr", gt)
    assert spadgen.open_run(run).depth().shape == (10, 10)
    for name in ("laser.exr", "labels.exr", "sensor_maps.exr", "ambient.exr"):
        data = (run / name).read_bytes()
        assert data.count(b"[507,245,10,10]") == 1
        (run / name).write_bytes(data.replace(b"[507,245,10,10]", b"[508,245,10,10]"))
        with pytest.raises(ValueError, match=f"{run / name}: its header's spadgen_crop is \\[508,245,10,10\\], but "
                                             "metadata.json's image.crop_in_sensor is \\[507, 245, 10, 10\\]"):
            spadgen.open_run(run)[name]
        (run / name).write_bytes(data)
    # the sensor maps and labels of another chip (seeds.chip), said by their header's spadgen_chip_seed
    import struct
    chip = str(spadgen.open_run(run).metadata["seeds"]["chip"])
    other = str((int(chip[0]) + 1) % 10) + chip[1:]
    for name in ("labels.exr", "sensor_maps.exr"):
        data = (run / name).read_bytes()
        attribute = b"spadgen_chip_seed\0string\0" + struct.pack("<i", len(chip))
        assert data.count(attribute + chip.encode()) == 1, name
        (run / name).write_bytes(data.replace(attribute + chip.encode(), attribute + other.encode()))
        with pytest.raises(ValueError, match=f"{run / name}: its header's spadgen_chip_seed is {other}, but metadata.json's "
                                             f"seeds.chip is {chip}: the file is of another chip"):
            spadgen.open_run(run)[name]
        (run / name).write_bytes(data)
    (run / "detections_edges.exr").mkdir()
    with pytest.raises(spadgen.ExrError, match=f"{run / 'detections_edges.exr'}: not a regular file"):
        spadgen.open_run(run).detections()


def test_what_a_run_did_not_write_is_named(make_run, tmp_path):
    posed = spadgen.open_run(make_run("posed"))
    with pytest.raises(FileNotFoundError, match="outputs.frames"):
        posed.frames_packed
    with pytest.raises(FileNotFoundError, match="outputs.transient"):
        posed.transient
    with pytest.raises(FileNotFoundError, match="no metadata.json"):
        spadgen.open_run(tmp_path)
    (tmp_path / "metadata.json").write_text(json.dumps({"files": []}))
    with pytest.raises(KeyError, match="no camera section"):
        spadgen.open_run(tmp_path).intrinsics


def test_rising_edge_baseline_on_the_flat_target(make_run):
    run = spadgen.open_run(make_run("flat"))
    truth = run.depth()
    # Noise-free profiles: the timing chain agrees with the geometry within 3 mm (as tests/app/paper_test.cpp).
    err0 = rising_edge_range(run, expected=True) - truth
    assert np.isfinite(err0).all() and np.abs(err0).max() < 3e-3
    # Sampled counts at 0.8 m: the paper's figures (accuracy 1.9 mm, precision 2.7 mm) with margin.
    err = rising_edge_range(run) - truth
    assert np.isfinite(err).all() and abs(err.mean()) < 5e-3 and err.std() < 8e-3
    # and no bias from the noise: the mean within 4 standard errors of the noise-free one (a false alarm of
    # 6e-5; the plateau taken from the noisy top made it 2.1 mm far here, 8 standard errors)
    assert abs(err.mean() - err0.mean()) < 4 * err.std() / np.sqrt(err.size)


def test_rising_edge_baseline_under_ambient_light(make_run):
    # The half level is the photon midpoint of the profile's floor (ambient light, dark counts) and its
    # plateau: half the top from zero lay below a lit profile's floor (a plane at 0.4 m read 3.4 mm near at
    # 100 lux, and no pixel at all at 300 lux).
    dark, lit = spadgen.open_run(make_run("flat")), spadgen.open_run(make_run("flat_lit"))
    ec = np.asarray(lit.expected_counts[...], np.float64)
    assert np.median(ec.min(axis=0) / ec.max(axis=0)) > 0.1  # the floor the test is about
    truth = lit.depth()
    est = rising_edge_range(lit, expected=True)
    assert np.isfinite(est).all() and np.abs(est - truth).max() < 3e-3
    # the ambient light moves no edge: the same ranges as in the dark within 0.3 mm
    assert np.abs(est - rising_edge_range(dark, expected=True)).max() < 3e-4


def test_detections_of_spadgen_reconstruct(spadgen_bin, make_run, tmp_path):
    # A copy of the sweep run, so that the shared fixture's folder stays as the run wrote it.
    import shutil
    import subprocess

    run_dir = tmp_path / "run"
    shutil.copytree(make_run("sweep"), run_dir)
    run = spadgen.open_run(run_dir)
    with pytest.raises(FileNotFoundError, match="spadgen reconstruct"):
        run.detections("paper")
    subprocess.run([spadgen_bin, "reconstruct", str(run_dir), "--detector", "paper", "-q"], check=True)
    d = run.detections("paper")
    assert d.detector["detector"] == "paper" and d.detector["parameters"]["window"] == 60
    # a file written elsewhere (reconstruct -o), whatever its detector: read from there, of this run
    subprocess.run([spadgen_bin, "reconstruct", str(run_dir), "--detector", "paper", "-q", "-o", str(tmp_path / "p.exr")], check=True)
    elsewhere = run.detections(path=tmp_path / "p.exr")
    assert elsewhere.detector["detector"] == "paper"
    np.testing.assert_array_equal(elsewhere.count, d.count)
    assert d.count.shape == (run.height, run.width) and d.range.shape[1:] == (run.height, run.width)
    # the slots hold count returns each, in increasing range, NaN beyond
    finite = np.isfinite(d.range)
    assert (finite.sum(axis=0) == d.count).all()
    r = np.where(finite, d.range, np.inf)
    assert (np.diff(r, axis=0)[np.isfinite(r[1:])] >= 0).all()
    # the channels as the EXR holds them
    exr = spadgen.ExrFile(run_dir / "detections_paper.exr")
    assert np.array_equal(d.range[0], exr["det0.range"], equal_nan=True)
    # from the expected counts: a file of its own, read with noise_free=True; the sampled one stays
    with pytest.raises(FileNotFoundError, match="--noise-free"):
        run.detections("paper", noise_free=True)
    subprocess.run([spadgen_bin, "reconstruct", str(run_dir), "--detector", "paper", "--noise-free", "-q"], check=True)
    nf = run.detections("paper", noise_free=True)
    assert nf.detector["noise_free"] is True and d.detector["noise_free"] is False
    assert np.array_equal(run.detections("paper").range, d.range, equal_nan=True)
    # a file under another detector's name (a copy) is refused, naming whose it is (it was read as that detector's)
    shutil.copy(run_dir / "detections_paper_noise_free.exr", run_dir / "detections_edges.exr")
    with pytest.raises(ValueError, match="written by reconstruct's paper detector on the noise-free rates, not the edges detector"):
        run.detections("edges")
    # detections of another run: of another size, or of the same size but another crop (the header's source)
    other = tmp_path / "other"
    shutil.copytree(make_run("light_only"), other)
    shutil.copy(run_dir / "detections_paper.exr", other / "detections_paper.exr")
    with pytest.raises(ValueError, match=f"{other / 'detections_paper.exr'}: a 347 x 10 image, but metadata.json's image is 10 x 10"):
        spadgen.open_run(other).detections("paper")
    data = (run_dir / "detections_paper.exr").read_bytes()
    assert data.count(b'"crop_in_sensor":[490,236,347,10]') == 1
    (run_dir / "detections_paper.exr").write_bytes(data.replace(b"[490,236,347,10]", b"[491,236,347,10]"))
    with pytest.raises(ValueError, match="detections_paper.exr: the detections are of another crop of the sensor than .*: \\[491, 236, 347, 10\\]"):
        spadgen.open_run(run_dir).detections("paper")


# What a Run gives, read one by one in the soak below (each a property, or a method without arguments).
_RUN_READS = ("width", "height", "crop", "units", "seed", "seeds", "spadgen_version", "acquisition", "mode", "K",
              "frames_per_k", "gate_positions_s", "gate_positions_ns", "exposures_s", "time_axis", "detection_rate",
              "expected_counts", "counts", "frames_packed", "ambient", "sensor_maps", "depth", "hit", "layers",
              "object_slots", "labels", "layer_count", "intrinsics", "camera_to_world", "world_to_camera", "point_cloud",
              "laser", "ground_truth", "objects")


def test_a_damaged_metadata_json_is_named_by_every_reader(make_run, tmp_path):
    """metadata.json damaged at random places (150 cases from a fixed seed: a value of another type or out of
    range, a key or element removed), then everything a Run gives read: a ValueError or OSError naming what is
    wrong, or a KeyError for a key a run of another spadgen version lacks, never a TypeError, IndexError or
    bare KeyError from wherever it was read (a soak of 4,000 cases found camera.intrinsics, camera_to_world,
    ground_truth_layers and ground_truth_objects of other types read so)."""
    import random
    import shutil
    from conftest import damage_at, damage_json
    run = tmp_path / "run"
    shutil.copytree(make_run("light_only"), run)
    original = (run / "metadata.json").read_text()
    meta = json.loads(original)
    rng = random.Random(20261207)
    named = 0
    # the soak's finds first, then the random cases
    found = [(("camera", "camera_to_world", 3, 0), {"a": 1}), (("camera", "camera_to_world"), -1),
             (("camera", "camera_to_world"), []), (("camera", "intrinsics", 0, 2), "x"), (("ground_truth_layers",), {}),
             (("ground_truth_objects",), None), (("ground_truth_objects",), {"a": 1})]
    for c in range(len(found) + 150):
        m = json.loads(original)
        what = damage_at(m, *found[c]) if c < len(found) else damage_json(m, rng)
        (run / "metadata.json").write_text(json.dumps(m))
        try:
            r = spadgen.open_run(run)
        except (ValueError, OSError):
            named += 1
            continue
        for name in _RUN_READS:
            try:
                v = getattr(r, name)
                v = v() if callable(v) else v
                np.asarray(v) if isinstance(v, np.ndarray) else None
            except (ValueError, OSError, FileNotFoundError):
                named += 1
            except KeyError as e:
                assert "the run was written by spadgen" in str(e) or "no channel" in str(e), f"{name} with {what}: {e!r}"
                named += 1
            except AttributeError as e:
                assert f"no attribute {name!r}" not in str(e), f"{name} is not a reader of Run"
                raise AssertionError(f"{name} with {what}: {e!r}") from e
    (run / "metadata.json").write_text(original)
    assert named > 30, "the damage is read, and named, not ignored wholesale"
    assert meta == json.loads((run / "metadata.json").read_text())
