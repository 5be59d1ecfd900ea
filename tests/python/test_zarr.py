"""Zarr stores (outputs.storage = zarr) read by an independent reader, zarr-python: the writer's arrays
against the same arrays written as .npy (uint8, uint16, float32 and the saved light's types, shapes that are
not multiples of the chunks, tiles written in any order), and the Python package on a run stored as Zarr
against the same run stored as .npy, through the same API."""
import json
import math
import subprocess

import numpy as np
import pytest

from spadgen import open_run

zarr = pytest.importorskip("zarr")

CASES = {  # name: chunks as written (before clipping to the shape)
    "khw_u8": (37, 32, 64), "khw_u16": (2, 32, 64), "khw_f32": (4, 16, 32), "khw_f32_one_chunk": (3, 32, 64),
    "hwt_f32": (8, 64, 50), "values_f32": (4096,), "offsets_i64": (1024,), "image_f64": (256, 256),
    "ranges_i32": (16, 16, 2), "empty_u8": (4, 4),
}


@pytest.fixture(scope="module")
def written(zarr_tool, tmp_path_factory):
    out = tmp_path_factory.mktemp("zarr")
    subprocess.run([zarr_tool, "write", str(out)], check=True)
    return out


def same_bytes(a, b):
    """Equal dtype, shape and bytes (NaN payloads, -0.0 and subnormals included)."""
    a, b = np.ascontiguousarray(a), np.ascontiguousarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.mark.parametrize("name", sorted(CASES))
def test_zarr_python_reads_what_numpy_reads(written, name):
    expected = np.load(written / f"{name}.npy")
    z = zarr.open_array(str(written / f"{name}.zarr"), mode="r")
    assert z.dtype == expected.dtype and z.shape == expected.shape
    assert same_bytes(z[...], expected)
    # Parts crossing chunk boundaries, as a reader takes them.
    if expected.ndim == 3 and expected.size:
        assert same_bytes(z[:, 3:40, 17:66], expected[:, 3:40, 17:66])
        assert same_bytes(z[-1, :, -1], expected[-1, :, -1])
    # The metadata: chunks clipped to the shape, Blosc zstd, C order, the fill value NaN for floats (none for
    # integers: every value can be a sample's), the attributes given.
    meta = json.loads((written / f"{name}.zarr" / ".zarray").read_text())
    assert meta["zarr_format"] == 2 and meta["order"] == "C" and meta["filters"] is None
    assert meta["fill_value"] == ("NaN" if expected.dtype.kind == "f" else None)
    assert tuple(meta["chunks"]) == tuple(max(1, min(c, s)) for c, s in zip(CASES[name], expected.shape))
    assert meta["compressor"]["id"] == "blosc" and meta["compressor"]["cname"] == "zstd"
    assert meta["compressor"]["shuffle"] == (0 if expected.dtype == np.uint8 else 1)
    assert z.attrs["case"] == name
    # Every chunk stored, one file each, named by its grid indices.
    grid = [math.ceil(s / c) for s, c in zip(expected.shape, meta["chunks"])]
    chunk_files = {p.name for p in (written / f"{name}.zarr").iterdir() if not p.name.startswith(".")}
    assert chunk_files == {".".join(map(str, i)) for i in np.ndindex(*grid)}


def test_a_zarr_run_reads_as_its_npy_run_through_the_package(make_run):
    npy, zr = open_run(make_run("sweep")), open_run(make_run("sweep_zarr"))
    assert any(f.endswith(".zarr") for f in zr.files) and not any(f.endswith(".zarr") for f in npy.files)
    assert zr.metadata["storage"]["stacks"] == "zarr" and npy.metadata["storage"]["stacks"] == "npy"
    stacks = ["counts", "detection_rate", "expected_counts", "transient", "transient_indirect", "light/values",
              "light/ranges", "light/offsets", "light/laser_total", "light/out_of_window", "light/ambient_rate"]
    for name in stacks:
        assert zr.has(name + ".npy") and zr.has(name) and zr.has(name + ".zarr"), name
        assert f"{name}.zarr" in zr.files and f"{name}.npy" in npy.files, name
        assert same_bytes(zr[name][...], npy[name][...]), name
        assert zr.metadata["storage"]["files"][f"{name}.zarr"]["format"] == "zarr"
    # The frames stay a .npy (random bits do not compress).
    assert "frames.npy" in zr.files and same_bytes(zr.frames(3), npy.frames(3))
    for prop in ("counts", "detection_rate", "expected_counts", "transient", "transient_indirect"):
        assert same_bytes(np.asarray(getattr(zr, prop)), np.asarray(getattr(npy, prop))), prop
    p, q = zr.gate_profile(200, 4), npy.gate_profile(200, 4)
    assert np.array_equal(p.gate_ns, q.gate_ns) and same_bytes(p.values, q.values)
    assert same_bytes(zr.gate_profile(200, 4, expected=True).values, npy.gate_profile(200, 4, expected=True).values)
    assert np.array_equal(zr.depth(), npy.depth(), equal_nan=True)
    # The metadata differs in the storage record only (its files and their sizes, and how the run went).
    a, b = dict(zr.metadata), dict(npy.metadata)
    for m in (a, b):
        for key in ("run", "storage", "files", "file_bytes", "scene_hash_fnv1a64"):
            m.pop(key)
        m["resolved_scene"]["outputs"].pop("storage")
    assert a == b


def test_the_dataset_gives_the_same_samples(make_run):
    torch = pytest.importorskip("torch")
    from spadgen.torchdata import RunDataset
    fields = ("counts", "expected_counts", "detection_rate", "depth", "mask")
    a = RunDataset([make_run("sweep")], fields=fields, patch_size=8)
    b = RunDataset([make_run("sweep_zarr")], fields=fields, patch_size=8)
    assert len(a) == len(b)
    for i in (0, len(a) // 2, len(a) - 1):
        for key, value in a[i].items():
            if key != "run":
                assert torch.equal(value, b[i][key]), key


def test_a_missing_zarr_stack_is_named(make_run):
    run = open_run(make_run("sweep_zarr"))
    with pytest.raises(FileNotFoundError, match="outputs.light"):
        open_run(make_run("intensity"))["light/values"]
    assert not run.has("nothing.npy")


def test_xarray_opens_a_zarr_run_as_a_dataset(make_run):
    """The run folder and light/ are Zarr groups: xarray opens their stores lazily, with named dimensions
    and the values as stored (the float stores' fill value is NaN: masking it leaves every value as it is)."""
    xr = pytest.importorskip("xarray")
    npy, path = open_run(make_run("sweep")), make_run("sweep_zarr")
    ds = xr.open_zarr(str(path), consolidated=False)
    assert ds["counts.zarr"].dims == ("k", "y", "x") and ds["counts.zarr"].dtype == np.uint8
    assert same_bytes(ds["counts.zarr"].values, npy.counts[...])
    assert same_bytes(ds["detection_rate.zarr"].values, npy.detection_rate[...])
    assert ds["transient.zarr"].dims == ("y_transient", "x_transient", "t")
    light = xr.open_zarr(str(path), group="light", consolidated=False)
    assert same_bytes(light["values.zarr"].values, npy["light/values"][...])
    assert set(zarr.open_group(str(path), mode="r").array_keys()) >= {"counts.zarr", "detection_rate.zarr"}


def test_a_missing_chunk_is_an_error_naming_it(make_run, tmp_path):
    """spadgen writes every chunk: a chunk removed afterwards read as uninitialised memory (counts of 64304 in a
    run of 300 frames). Through the package it is an error naming the chunk, also in a float store, whose fill
    value is NaN; a plain Zarr reader reads a lost float chunk as NaN (it read uninitialised memory when the
    stores had no fill value), the integer stores have none (every value can be a sample's)."""
    import os
    import shutil
    run_dir = tmp_path / "run"
    shutil.copytree(make_run("sweep_zarr"), run_dir)
    store = run_dir / "counts.zarr"
    chunks = sorted(n for n in os.listdir(store) if not n.startswith("."))
    assert chunks
    whole = np.asarray(open_run(run_dir).counts)  # every chunk there: reads
    assert whole.max() <= open_run(run_dir).frames_per_k
    os.remove(store / chunks[-1])
    with pytest.raises(FileNotFoundError, match=f"{store / chunks[-1]}: a chunk of this Zarr store is missing"):
        np.asarray(open_run(run_dir).counts)
    rate = run_dir / "detection_rate.zarr"
    whole = np.asarray(open_run(run_dir).detection_rate)
    assert whole.dtype.kind == "f" and np.isfinite(whole).all()
    meta = json.loads((rate / ".zarray").read_text())
    lost = sorted(n for n in os.listdir(rate) if not n.startswith("."))[0]
    os.remove(rate / lost)
    with pytest.raises(FileNotFoundError, match=f"{rate / lost}: a chunk of this Zarr store is missing"):
        np.asarray(open_run(run_dir).detection_rate)
    plain = zarr.open_array(str(rate), mode="r")[...]
    region = tuple(slice(int(i) * c, (int(i) + 1) * c) for i, c in zip(lost.split("."), meta["chunks"]))
    assert np.isnan(plain[region]).all()
    inside = np.zeros(whole.shape, dtype=bool)
    inside[region] = True
    assert same_bytes(plain[~inside], whole[~inside])


def test_the_counts_check_decodes_each_chunk_once(make_run, monkeypatch):
    """Run.counts checks every count against frames_per_k in blocks of whole chunks: it read k by k, and as a
    chunk spans every k it decoded each chunk K / (blocks of k) times (6 to 11 times on a 1024 x 1000 run). With
    blocks far smaller than the store (as a large run's are against 64 MB), every chunk is read exactly once."""
    import spadgen.run as module
    reads = []
    strict = module._zarr_store

    def counting(path, z=None, check=None):
        store = strict(path, z, check)
        get = store.__getitem__

        class Counting(type(store)):
            def __getitem__(self, key):
                if not key.startswith("."):
                    reads.append(key)
                return get(key)
        store.__class__ = Counting
        return store

    monkeypatch.setattr(module, "_zarr_store", counting)
    run = open_run(make_run("sweep_zarr"))
    z = run.array("counts")
    K, H, W = z.shape
    monkeypatch.setattr(module, "_CHECK_BLOCK_BYTES", 1)  # a block of one chunk's rows
    # uint8 counts of 255 frames need no check (none can exceed N): as if of 254 frames, which need one
    assert z.dtype == np.uint8 and run.frames_per_k == 255 and np.asarray(z).max() <= 254
    run.metadata["acquisition"]["frames_per_k"] = 254
    reads.clear()
    run.counts
    every = [".".join(str(i) for i in c) for c in np.ndindex(*(math.ceil(n / c) for n, c in zip(z.shape, z.chunks)))]
    assert len(every) > 1
    assert sorted(reads) == sorted(every)


def test_a_cut_short_chunk_is_an_error_naming_it(make_run, tmp_path):
    """A chunk cut short (a full disk, an interrupted copy) made Blosc say only "error during blosc
    decompression: -1": the error names the chunk and the sizes; one of the right length reads as before."""
    import os
    import shutil
    run_dir = tmp_path / "run"
    shutil.copytree(make_run("sweep_zarr"), run_dir)
    store = run_dir / "counts.zarr"
    chunk = store / sorted(n for n in os.listdir(store) if not n.startswith("."))[0]
    data = chunk.read_bytes()
    assert int.from_bytes(data[12:16], "little") == len(data)  # the header spadgen wrote states the chunk's size
    expected = np.asarray(open_run(run_dir).counts)
    for cut in (len(data) - 1, 100, 10):
        chunk.write_bytes(data[:cut])
        with pytest.raises(OSError, match=f"{chunk}: a chunk of this Zarr store holds {cut} bytes"):
            np.asarray(open_run(run_dir).counts)
    chunk.write_bytes(data)
    assert same_bytes(np.asarray(open_run(run_dir).counts), expected)


def test_a_zarray_spadgen_does_not_write_is_refused_naming_the_store(make_run, tmp_path):
    """.zarray edited after the run published it: order "F" was read as if C order (every element moved, also
    through torchdata), a dtype edited gave "cannot reshape array of size ..." naming nothing; the fields the
    program's reader checks (writers/zarr.cpp) are checked as it does, the error naming the store."""
    import shutil
    run_dir = tmp_path / "run"
    shutil.copytree(make_run("sweep_zarr"), run_dir)
    store = run_dir / "counts.zarr"
    good = json.loads((store / ".zarray").read_text())
    expected = np.asarray(open_run(run_dir).counts)
    for key, value, says in (("order", "F", "order is \"F\": only C order is supported"),
                             ("dtype", "<u2", "dtype <u2, but the run writes counts as uint8"),
                             ("dtype", ">f4", "dtype \">f4\" is not one spadgen writes"),
                             ("filters", [{"id": "delta", "dtype": "|u1"}], "filters are not supported"),
                             ("compressor", {"id": "zlib"}, "only Blosc \\(or none\\) is supported"),
                             ("fill_value", "x", "fill_value \"x\" is not a number"),
                             ("fill_value", -5, "fill_value -5 is not an integer in the range of dtype \\|u1"),
                             ("fill_value", 256, "fill_value 256 is not an integer in the range of dtype \\|u1"),
                             ("fill_value", 1.5, "fill_value 1.5 is not an integer in the range of dtype \\|u1"),
                             ("fill_value", 10 ** 400, "fill_value 1000.* is not an integer in the range"),
                             ("shape", [good["shape"][0], 2, 3], "shape \\(.*\\), but metadata.json's \\(K, H, W\\) is"),
                             ("chunks", [0, 1, 1], "chunks \\[0, 1, 1\\] is not a list of positive integers")):
        (store / ".zarray").write_text(json.dumps(dict(good, **{key: value})))
        with pytest.raises(ValueError, match=f"{store}: .*{says}"):
            np.asarray(open_run(run_dir).counts)
    (store / ".zarray").write_text(json.dumps(dict(good, order="F")))
    pytest.importorskip("torch")
    from spadgen.torchdata import RunDataset
    with pytest.raises(ValueError, match=f"{store}: .*only C order"):
        RunDataset([run_dir], fields=("counts",))[0]
    # a stack whose dtype the run does not fix (the saved light's): its chunks decode to another size than
    # .zarray's chunks of the edited dtype take
    values = run_dir / "light" / "values.zarr"
    light = json.loads((values / ".zarray").read_text())
    wider = {"<f4": "<f8", "<f8": "<f4"}[light["dtype"]]
    (values / ".zarray").write_text(json.dumps(dict(light, dtype=wider)))
    with pytest.raises(ValueError, match=f"{values}/[0-9.]+: a chunk of this Zarr store decodes to"):
        np.asarray(open_run(run_dir)["light/values"][:])
    # a float store's fill value beyond its dtype's range (the saved light's values are float32)
    (values / ".zarray").write_text(json.dumps(dict(light, fill_value=1e39)))
    with pytest.raises(ValueError, match=f"{values}: .*fill_value 1e\\+39 is not a number in the range of dtype <f4"):
        np.asarray(open_run(run_dir)["light/values"][:])
    (store / ".zarray").write_text(json.dumps(good))
    assert same_bytes(np.asarray(open_run(run_dir).counts), expected)
