"""spadgen.torchdata.RunDataset: the documented keys, shapes and dtypes, values equal to the run's arrays,
patches with their intrinsics, batching with a DataLoader, a few steps of training, and the checks that
refuse runs that cannot share a batch. Skipped only where PyTorch is not installed (CI installs it)."""
import pickle
import os
import subprocess
import sys

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import spadgen  # noqa: E402
from spadgen.torchdata import FIELDS, RunDataset  # noqa: E402

from conftest import SCENES as SCENES_DIR  # noqa: E402


@pytest.fixture(scope="module")
def sweep(sweep_run):
    return spadgen.open_run(sweep_run)


def expected_layout(K, N, L, H, W, J):
    """The module docstring's table."""
    return {"counts": ((K, H, W), torch.float32), "expected_counts": ((K, H, W), torch.float32),
            "detection_rate": ((K, H, W), torch.float32),
            "depth": ((1, H, W), torch.float32), "depth_z": ((1, H, W), torch.float32), "mask": ((1, H, W), torch.bool), "layer_count": ((H, W), torch.int64),
            "layer_depth": ((L, H, W), torch.float32), "layer_mask": ((L, H, W), torch.bool),
            "object_count": ((H, W), torch.int64), "object_range": ((J, H, W), torch.float32),
            "object_mask": ((J, H, W), torch.bool), "object_detectable": ((J, H, W), torch.bool),
            "object_id": ((J, H, W), torch.int64), "object_path": ((J, H, W), torch.float32),
            "object_edge_snr": ((J, H, W), torch.float32),
            "frames": ((K, N, H, W), torch.uint8), "expected_counts_se": ((K, H, W), torch.float32),
            "pde": ((1, H, W), torch.float32), "pde_ambient": ((1, H, W), torch.float32), "dcr_cps": ((1, H, W), torch.float32),
            "ambient_photons_per_s": ((1, H, W), torch.float32), "laser_photons_per_pulse": ((1, H, W), torch.float32),
            "gate_positions_ns": ((K,), torch.float32),
            "frames_per_k": ((), torch.int64), "intrinsics": ((3, 3), torch.float32), "origin": ((2,), torch.int64),
            "run": ((), torch.int64)}


def test_whole_image_sample_has_the_documented_layout_and_values(sweep_run, sweep):
    ds = RunDataset([sweep_run], fields=FIELDS)
    assert len(ds) == 1
    # one folder alone is a list of one (a path was iterated as its characters: "o: no such folder"), also as a Path
    # or a Run
    for one in (str(sweep_run), sweep_run, spadgen.open_run(sweep_run)):
        alone = RunDataset(one, fields=("counts",))
        assert alone.paths == [str(sweep_run)] and torch.equal(alone[0]["counts"], ds[0]["counts"])
    s = ds[0]
    J = int(sweep.metadata["ground_truth_objects"])
    assert J >= 2  # the plate and the sphere along some rays
    layout = expected_layout(sweep.K, sweep.frames_per_k, 3, sweep.height, sweep.width, J)
    assert set(s) == set(layout)
    for key, (shape, dtype) in layout.items():
        assert tuple(s[key].shape) == shape and s[key].dtype == dtype, key
    np.testing.assert_array_equal(s["counts"].numpy(), sweep.counts)
    np.testing.assert_array_equal(s["expected_counts"].numpy(), sweep.expected_counts)
    np.testing.assert_array_equal(s["detection_rate"].numpy(), sweep.detection_rate)
    hit = sweep.hit()
    np.testing.assert_array_equal(s["mask"][0].numpy(), hit)
    np.testing.assert_array_equal(s["depth"][0].numpy(), np.where(hit, sweep.depth(), 0))
    # z depth: the range over the length of the pixel's ray direction (u - cx, v - cy) / f, 1, computed here from
    # the sample's intrinsics (pixel centres at integer coordinates)
    K = s["intrinsics"].numpy().astype(np.float64)
    v, u = np.mgrid[0:sweep.height, 0:sweep.width]
    norm = np.sqrt(1 + ((u - K[0, 2]) / K[0, 0]) ** 2 + ((v - K[1, 2]) / K[1, 1]) ** 2)
    z = s["depth_z"][0].numpy()
    assert not z[~hit].any()
    np.testing.assert_allclose(z[hit], (sweep.depth()[hit] / norm[hit]), rtol=2e-6)
    layers = sweep.layers()
    np.testing.assert_array_equal(s["layer_count"].numpy(), layers.count)
    np.testing.assert_array_equal(s["layer_depth"].numpy(), np.where(np.isfinite(layers.range), layers.range, 0))
    np.testing.assert_array_equal(s["layer_mask"].numpy().sum(0), layers.count)
    np.testing.assert_array_equal(s["frames"].sum(1).numpy(), sweep.counts)
    # the rendered light's error in the targets, and the chip's maps
    np.testing.assert_array_equal(s["expected_counts_se"].numpy(), sweep.expected_counts_error_bound())
    assert s["expected_counts_se"].numpy().max() > 0
    for name in ("pde", "pde_ambient", "dcr_cps"):
        np.testing.assert_array_equal(s[name][0].numpy(), sweep.sensor_maps[name])
    assert s["pde"].numpy().min() > 0
    # the noise-free flux, as the EXR files hold it (read here on their own)
    from spadgen.exr import ExrFile
    ambient = ExrFile(f"{sweep_run}/ambient.exr")["photons_per_second"]
    laser = ExrFile(f"{sweep_run}/laser.exr")["photons_per_pulse"]
    np.testing.assert_array_equal(s["ambient_photons_per_s"][0].numpy(), ambient)
    np.testing.assert_array_equal(s["laser_photons_per_pulse"][0].numpy(), laser)
    assert laser.max() > 0  # (this run has no ambient light: the 2D run below checks a lit one)
    # the objects, as evaluate scores them: Run.object_slots' (ground_truth.exr's and labels.exr's slots)
    slots = sweep.object_slots()
    used = slots.id >= 0
    np.testing.assert_array_equal(s["object_count"].numpy(), slots.count)
    np.testing.assert_array_equal(s["object_mask"].numpy(), used)
    np.testing.assert_array_equal(s["object_range"].numpy(), np.where(used, slots.range, 0))
    np.testing.assert_array_equal(s["object_detectable"].numpy(), slots.detectable & used)
    np.testing.assert_array_equal(s["object_id"].numpy(), np.where(used, slots.id, -1))
    np.testing.assert_array_equal(s["object_path"].numpy(), np.where(used, slots.path, 0))
    np.testing.assert_array_equal(s["object_edge_snr"].numpy(), np.where(used, slots.edge_snr, 0))
    # the time-of-flight truth: within a few mm of twice the range (the laser 3 cm beside the lens, a plate on the way)
    gap = s["object_path"].numpy()[used] - 2 * s["object_range"].numpy()[used]
    assert np.abs(gap).max() < 6e-3 and np.abs(gap).max() > 1e-4
    assert (s["object_edge_snr"].numpy()[used & slots.detectable] >= 5).all()
    # slot 0 holds the plate over part of the image and the sphere beside it: the id says which
    assert len(set(s["object_id"][0].numpy().ravel().tolist()) - {-1}) >= 2
    assert (s["object_count"] == 2).any() and s["object_detectable"][1].any()
    np.testing.assert_allclose(s["intrinsics"].numpy(), sweep.intrinsics, rtol=1e-7)
    assert s["origin"].tolist() == [0, 0] and int(s["run"]) == 0
    assert int(s["frames_per_k"]) == sweep.frames_per_k == 255


def test_an_intensity_runs_exposures_and_frames(make_run):
    dual = spadgen.open_run(make_run("intensity"))
    s = RunDataset([dual.path], fields=("counts",))[0]
    assert "gate_positions_ns" not in s and s["exposures_us"].dtype == torch.float32
    np.testing.assert_allclose(s["exposures_us"].numpy(), dual.exposures_s * 1e6, rtol=1e-7)
    assert s["exposures_us"].shape == (2,) and s["exposures_us"][1] > s["exposures_us"][0]  # short, long
    assert int(s["frames_per_k"]) == dual.frames_per_k and int(s["counts"].max()) <= dual.frames_per_k
    # a 2D run's HDR target: the ambient flux (this one traced no laser, and says so)
    flux = RunDataset([dual.path], fields=("ambient_photons_per_s",), patch_size=4)[1]["ambient_photons_per_s"]
    np.testing.assert_array_equal(flux[0].numpy(), dual.ambient["photons_per_second"][0:4, 4:8])
    assert flux.min() > 0
    if not dual.has("laser.exr"):
        with pytest.raises(ValueError, match="field 'laser_photons_per_pulse' needs laser.exr, which this run did not write"):
            RunDataset([dual.path], fields=("laser_photons_per_pulse",))


def test_patches_cover_the_image_and_shift_the_intrinsics(sweep_run, sweep):
    ds = RunDataset([sweep_run, sweep_run], patch_size=(5, 16), fields=("counts", "depth", "mask", "layer_count"),
                    max_layers=4)
    per_run = (10 // 5) * (347 // 16)
    assert len(ds) == 2 * per_run
    s = ds[per_run + 3]  # the second run's fourth patch: row 0, column 3
    assert int(s["run"]) == 1 and s["origin"].tolist() == [48, 0]
    assert tuple(s["counts"].shape) == (sweep.K, 5, 16)
    np.testing.assert_array_equal(s["counts"].numpy(), sweep.counts[:, 0:5, 48:64])
    # A patch pixel's ground-truth point projects onto that pixel with the patch's intrinsics.
    point = sweep.points()[2, 50]
    u, v = spadgen.project(point, s["intrinsics"].double().numpy())
    assert (u, v) == pytest.approx((50 - 48, 2), abs=1e-3)
    full = RunDataset([sweep_run], patch_size=(5, 16), fields=("layer_depth",), max_layers=4)[0]
    assert tuple(full["layer_depth"].shape) == (4, 5, 16) and not full["layer_depth"][3].any()
    objects = RunDataset([sweep_run], patch_size=(5, 16), fields=("object_range", "object_mask"), max_objects=3)[3]
    assert tuple(objects["object_range"].shape) == (3, 5, 16) and not objects["object_mask"][2].any()
    slots = sweep.object_slots()
    np.testing.assert_array_equal(objects["object_range"][:2].numpy(),
                                  np.where(slots.id[:2, 0:5, 48:64] >= 0, slots.range[:2, 0:5, 48:64], 0))
    # a patch's error and maps are the whole image's there
    maps = RunDataset([sweep_run], patch_size=(5, 16), fields=("expected_counts_se", "dcr_cps"))[3]
    np.testing.assert_array_equal(maps["expected_counts_se"].numpy(), sweep.expected_counts_error_bound()[:, 0:5, 48:64])
    np.testing.assert_array_equal(maps["dcr_cps"][0].numpy(), sweep.sensor_maps["dcr_cps"][0:5, 48:64])


def test_patches_at_a_stride_overlap(sweep_run, sweep):
    ds = RunDataset([sweep_run], patch_size=(5, 16), patch_stride=(2, 7), fields=("counts",))
    origins = [ds[j]["origin"].tolist() for j in range(len(ds))]
    assert origins == [[x, y] for y in (0, 2, 4) for x in range(0, 347 - 16 + 1, 7)]
    np.testing.assert_array_equal(ds[len(origins) // 3 + 2]["counts"].numpy(), sweep.counts[:, 2:7, 14:30])
    assert len(RunDataset([sweep_run], patch_size=(5, 16), patch_stride=1, fields=("counts",))) == 6 * 332
    with pytest.raises(ValueError, match="patch_stride 2 without patch_size"):
        RunDataset([sweep_run], patch_stride=2)
    with pytest.raises(ValueError, match="patch_stride must be an integer >= 1, got 0"):
        RunDataset([sweep_run], patch_size=4, patch_stride=(0, 1))


def test_data_loader_batches_and_a_training_step(sweep_run, sweep):
    ds = RunDataset([sweep_run], patch_size=8)
    loader = torch.utils.data.DataLoader(ds, batch_size=4, shuffle=True, generator=torch.Generator().manual_seed(0))
    batch = next(iter(loader))
    assert tuple(batch["counts"].shape) == (4, sweep.K, 8, 8) and tuple(batch["mask"].shape) == (4, 1, 8, 8)
    # a Subset of tensor indices, as torch.randperm gives them (0-d tensors reach __getitem__)
    subset = torch.utils.data.Subset(ds, torch.randperm(len(ds), generator=torch.Generator().manual_seed(1))[:2])
    assert torch.equal(subset[0]["counts"], ds[int(subset.indices[0])]["counts"])
    with pytest.raises(IndexError, match=rf"RunDataset\[{len(ds)}\] is past its {len(ds)} items"):
        ds[len(ds)]
    # docs/python.md's loop, shortened: counts -> depth with a 1 x 1 convolution, masked L1 loss.
    torch.manual_seed(0)
    net = torch.nn.Conv2d(sweep.K, 1, 1)
    opt = torch.optim.Adam(net.parameters(), lr=5e-2)
    losses = []
    for _ in range(3):
        for b in loader:
            pred = net(b["counts"] / sweep.frames_per_k)
            loss = ((pred - b["depth"]).abs() * b["mask"]).sum() / b["mask"].sum().clamp(min=1)
            opt.zero_grad()
            loss.backward()
            opt.step()
            losses.append(loss.item())
    assert np.isfinite(losses).all() and np.mean(losses[-5:]) < 0.5 * np.mean(losses[:5])
    # The dataset pickles without its open memory maps (DataLoader workers open their own).
    again = pickle.loads(pickle.dumps(ds))
    np.testing.assert_array_equal(again[1]["counts"].numpy(), ds[1]["counts"].numpy())
    # twice from one run in the copy (a spawned worker's: the cache came back as a dict, without move_to_end)
    np.testing.assert_array_equal(again[0]["counts"].numpy(), ds[0]["counts"].numpy())
    np.testing.assert_array_equal(again[1]["counts"].numpy(), ds[1]["counts"].numpy())
    # workers started by spawn (macOS's and Windows's default) get the dataset pickled: every patch once
    spawned = torch.utils.data.DataLoader(ds, batch_size=None, num_workers=2, multiprocessing_context="spawn")
    seen = sorted(tuple(b["origin"].tolist()) for b in spawned)
    assert seen == sorted(tuple(ds[j]["origin"].tolist()) for j in range(len(ds)))


def test_runs_that_cannot_share_a_batch_are_refused(sweep_run, make_run, spadgen_bin, tmp_path):
    posed = make_run("posed")
    with pytest.raises(ValueError, match=r"different K .*cannot share a batch; make one per K \(of a dataset, "
                                         r"DatasetSamples\(ds.select\(...\)\)"):
        RunDataset([sweep_run, posed])
    with pytest.raises(ValueError, match=r"needs frames, which this run did not write \(written with outputs.frames\)"):
        RunDataset([posed], fields=("frames",))
    with pytest.raises(ValueError, match="unknown field"):
        RunDataset([sweep_run], fields=("count",))
    # a gate sweep and a 2D run of the same K (it failed in the batch, KeyError 'gate_positions_ns')
    sweep2 = tmp_path / "sweep2"
    subprocess.run([spadgen_bin, "run", str(SCENES_DIR / "multi_object.json"), "--set", "camera.crop=[500,240,4,4]",
                    "--set", "render.samples_per_pixel=1", "--set", "acquisition.gate_sweep.start_ns=3",
                    "--set", "acquisition.gate_sweep.stop_ns=3.036", "--set", "outputs.previews=false", "-o", str(sweep2), "-q"],
                   check=True)
    dual = make_run("intensity")
    assert spadgen.open_run(sweep2).K == spadgen.open_run(dual).K == 2
    with pytest.raises(ValueError, match="different acquisition modes"):
        RunDataset([sweep2, dual], fields=("counts",))
    with pytest.raises(ValueError, match="no run is as large"):
        RunDataset([sweep_run], patch_size=(11, 8))
    # sizes that are not whole numbers were cut (7.9 to 7) or failed later with a bare message
    for bad, match in [(7.9, "patch_size must be an integer >= 1, got 7.9"), ((8,), r"a pair \(h, w\) of integers, got \(8,\)"),
                       ((0, 8), "patch_size must be an integer >= 1, got 0"), (True, "got True")]:
        with pytest.raises(ValueError, match=match):
            RunDataset([sweep_run], patch_size=bad)
    with pytest.raises(ValueError, match="max_layers must be an integer >= 0, got -1"):
        RunDataset([sweep_run], max_layers=-1)


def test_import_spadgen_does_not_import_torch():
    code = "import sys, spadgen; print('torch' in sys.modules); spadgen.RunDataset; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True).stdout.split()
    assert out == ["False", "True"]


def test_a_run_without_noise_free_rates_says_how_to_get_them(make_run, spadgen_bin, tmp_path):
    """A run that saved the light but no rates (the shipped dataset example's storage): the default fields ask
    for expected_counts, and the error names the sense command that writes it; that command's folder loads."""
    run = make_run("light_only")
    with pytest.raises(ValueError, match=r"spadgen sense .* --set outputs.expected_counts=true -o DIR") as e:
        RunDataset([run])
    assert "or leave 'expected_counts' out of fields (e.g. fields=('counts', 'depth', 'mask', 'layer_count'))" in str(e.value)
    assert RunDataset([run], fields=("counts", "depth", "mask", "layer_count"))[0]["counts"].shape[1:] == (10, 10)
    # Run.expected_counts says the same (it raised "did not write expected_counts.npy", silent on the rates)
    with pytest.raises(FileNotFoundError, match=r"wrote neither expected_counts nor detection_rate.*spadgen sense .* "
                                                r"--set outputs.detection_rate=true -o DIR"):
        spadgen.open_run(run).expected_counts
    # a run without ground_truth.exr: the suggestion leaves out every field that needs it (it named mask and
    # layer_count, which fail next)
    no_truth = tmp_path / "no_truth"
    subprocess.run([spadgen_bin, "run", str(SCENES_DIR / "flat_target.json"), "--set", "camera.crop=[507,245,4,4]",
                    "--set", "render.samples_per_pixel=1", "--set", "outputs.ground_truth=false", "--set",
                    "outputs.previews=false", "-o", str(no_truth), "-q"], check=True)
    with pytest.raises(ValueError, match="field 'depth' needs ground_truth.exr") as e:
        RunDataset([no_truth])
    assert "or leave 'depth' out of fields (e.g. fields=('counts', 'expected_counts'))" in str(e.value)
    assert RunDataset([no_truth], fields=("counts", "expected_counts"))[0]["counts"].shape[1:] == (4, 4)
    # a file the run lists, lost since: refused by the constructor, named (it failed at the item reading it)
    import shutil
    shutil.copytree(no_truth, tmp_path / "lost")
    os.remove(tmp_path / "lost" / "counts.npy")
    with pytest.raises(ValueError, match=r"lost/counts.npy: listed in .*metadata.json \(files\) but missing, and field "
                                         r"'counts' reads it: the run folder is damaged"):
        RunDataset([tmp_path / "lost"], fields=("counts",))
    out = tmp_path / "sensed"
    subprocess.run([spadgen_bin, "sense", str(run), "--set", "outputs.expected_counts=true", "-o", str(out), "-q"], check=True)
    sensed = RunDataset([out])[0]
    np.testing.assert_array_equal(sensed["counts"].numpy(), RunDataset([run], fields=("counts",))[0]["counts"].numpy())
    assert sensed["expected_counts"].shape == sensed["counts"].shape


def _small_run(spadgen_bin, out, seed, storage, crop="[507,245,16,8]"):
    subprocess.run([spadgen_bin, "run", str(SCENES_DIR / "flat_target.json"), "-o", str(out), "-q", "--seed", str(seed),
                    "--set", f"camera.crop={crop}", "--set", "render.samples_per_pixel=1",
                    "--set", f"outputs.storage={storage}", "--set", "outputs.previews=false"], check=True)


@pytest.mark.parametrize("storage", ["npy", "zarr"])
def test_a_run_folder_replaced_while_in_use_is_an_error_not_two_versions(spadgen_bin, tmp_path, storage):
    """A run published again into a folder in use (as a dataset run regenerating a stale sample does): Zarr
    chunks are read by path, so the next item would hold the new counts and the old decoded depth; every item
    is read between two checks of the folder, and a worker opening it later compares it with the one checked
    at construction. A new dataset object reads the new version."""
    out = tmp_path / "run"
    _small_run(spadgen_bin, out, 1, storage)
    ds = RunDataset([out])
    first = ds[0]
    run = spadgen.open_run(out)
    assert run.unchanged()
    counts = run.counts  # opened before the swap (a memory map, or a zarr.Array reading its chunks by path)
    before = np.array(counts[:])
    gt_header = spadgen.open_run(out).ground_truth  # its header read, its channels not yet decoded
    _small_run(spadgen_bin, out, 2, storage, crop="[100,100,24,16]")
    assert not run.unchanged()
    with pytest.raises(spadgen.RunChangedError, match=f"{out}: the run folder was replaced since it was opened"):
        run.check_unchanged()
    # a file the Run opens after the swap is the newer run's: refused (the depth of a 24 x 16 crop beside the
    # metadata of a 16 x 8 one was read, and points() built from the two without a word)
    for read in (lambda: run.depth(), lambda: run.detection_rate, lambda: run.ground_truth):
        with pytest.raises(spadgen.RunChangedError, match=f"{out}: the run folder was replaced since it was opened"):
            read()
    # the counts opened before: a memory map reads the version it opened; a Zarr array refuses (it read the new
    # run's chunks under the old metadata, silently)
    if storage == "npy":
        np.testing.assert_array_equal(counts[:], before)
    else:
        with pytest.raises(spadgen.RunChangedError, match=f"{out}: the run folder was replaced since it was opened"):
            counts[:]
    # an EXR whose header was read before the swap does not decode the newer file as its own
    with pytest.raises(spadgen.exr.ExrError, match="the file was replaced since its header was read"):
        gt_header["range"]
    with pytest.raises(spadgen.RunChangedError, match=str(out)):
        ds[0]
    # what a worker would do: a copy without its open runs, then opening the folder itself
    fresh_worker = pickle.loads(pickle.dumps(ds))
    with pytest.raises(spadgen.RunChangedError, match="replaced since RunDataset was made"):
        fresh_worker[0]
    again = RunDataset([out])[0]
    assert not torch.equal(again["counts"], first["counts"])  # another seed: the new version, whole
    np.testing.assert_array_equal(again["counts"].numpy(), np.asarray(spadgen.open_run(out).counts))


def test_counts_are_checked_once_per_run_not_per_opening(make_run, monkeypatch):
    """Run.counts checks every count against frames_per_k, once per Run object; a run closed to stay within
    open_runs and opened again (a shuffled loader over more runs than open_runs) was checked again, a whole pass
    over its counts per item. Once per run and process: of the same folder (its identity is checked on opening)."""
    checked = []
    check = spadgen.run.Run._check_counts
    monkeypatch.setattr(spadgen.run.Run, "_check_counts", lambda run, counts: (checked.append(run.path), check(run, counts)))
    run = make_run("intensity")
    assert np.iinfo(spadgen.open_run(run).counts.dtype).max > spadgen.open_run(run).frames_per_k  # (else not read)
    checked.clear()
    ds = RunDataset([run] * 3, fields=("counts",), open_runs=1)
    for _ in range(2):
        for j in range(len(ds)):
            ds[j]
    assert len(checked) == 3  # once per run: 6 before
    copy = pickle.loads(pickle.dumps(RunDataset([run] * 3, fields=("counts",), open_runs=1)))
    checked.clear()
    for j in (0, 1, 0, 1):
        copy[j]
    assert len(checked) == 2


def test_open_runs_are_bounded(sweep_run):
    """Each open run holds a file descriptor per memory-mapped stack (and its decoded ground truth): at most
    open_runs stay open, the least recently used closed first (600 runs of a dataset exhausted a limit of 1024
    descriptors)."""
    import os
    ds = RunDataset([sweep_run] * 200, fields=("counts", "expected_counts", "depth"), open_runs=8)
    before = len(os.listdir("/proc/self/fd"))
    for j in range(len(ds)):
        ds[j]
    assert len(ds._runs) == 8
    assert len(os.listdir("/proc/self/fd")) - before <= 8 * 2 + 4
    # the same in a pickled copy (a worker's): its cache evicts in order too
    copy = pickle.loads(pickle.dumps(ds))
    for j in range(20):
        copy[j]
    assert len(copy._runs) == 8 and list(copy._runs) == list(range(12, 20))
    with pytest.raises(ValueError, match="open_runs must be at least 1"):
        RunDataset([sweep_run], open_runs=0)
    with pytest.raises(ValueError, match=r"fields must be a list of field names, got the string 'counts'"):
        RunDataset([sweep_run], fields="counts")
