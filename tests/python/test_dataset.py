"""spadgen.open_dataset and spadgen.torchdata.DatasetSamples on a real small dataset (conftest.DATASET: 4
samples, sample 2 failed, 2 realisations each): the table against index.jsonl and index.csv read on their own,
selections, each sample's runs against open_run of its folders, realisations that differ in counts only, the
errors, and DatasetSamples' layout, length, values and DataLoader batches."""
import csv
import json
import math
import os
import subprocess

import numpy as np
import pytest

import spadgen
from spadgen.dataset import STATUSES, SUMMARY_COLUMNS
from conftest import DATASET, SCENES, SOURCE

WIDTHS = [1024, 1000, 16, 1024]  # the grid cell of sample i is i mod 3
DONE = [0, 1, 3]
NUMERIC = ("camera.width_px", "laser.average_power_mW", "ambient.illuminance_lux")


@pytest.fixture(scope="module")
def ds(dataset_dir):
    return spadgen.open_dataset(dataset_dir)


def jsonl_rows(dataset_dir):
    return [json.loads(line) for line in (dataset_dir / "index.jsonl").read_text().splitlines()]


def test_opening_reads_the_index_spec_and_card(ds, dataset_dir):
    assert len(ds) == 4 and [r["index"] for r in ds.index] == [0, 1, 2, 3]
    assert ds.index == jsonl_rows(dataset_dir)
    assert ds.spec == json.loads((dataset_dir / "dataset.json").read_text())
    assert ds.spec["repeats"] == 2 and ds.spec["dataset_file"].endswith("d.json")
    assert ds.card == (dataset_dir / "dataset.md").read_text() and ds.card.startswith("# python test dataset\n")
    assert ds.parameter_keys == ["scene", "camera.width_px", "laser.average_power_mW", "ambient.illuminance_lux",
                                 "sensor.preset"]
    assert ds.numeric_parameter_keys == list(NUMERIC)
    assert ds.status_counts() == {"done": 3, "failed": 1, "stale": 0, "missing": 0, "damaged": 0}
    assert repr(ds) == f"Dataset({str(dataset_dir)!r}, 4 samples: 3 done, 1 failed)"


def test_table_equals_index_jsonl_and_index_csv(ds, dataset_dir):
    rows = jsonl_rows(dataset_dir)
    with open(dataset_dir / "index.csv", newline="") as f:
        reader = csv.DictReader(f)
        header, records = reader.fieldnames, list(reader)
    t = ds.table()
    assert list(t) == ds.columns == header
    assert all(len(a) == 4 for a in t.values())
    for name in ("index", "seed", "seed_light", "seed_chip", "seed_noise"):
        assert t[name].dtype == np.int64, name
    for name in ("status", "folder", "sample_hash", "error", "scene", "sensor.preset"):
        assert t[name].dtype.kind == "U", name
    for name in ("bytes", "laser.average_power_mW", "ambient.illuminance_lux") + SUMMARY_COLUMNS:
        assert t[name].dtype == np.float64, name
    assert t["camera.width_px"].dtype == np.int64
    seeds = {"seed": "seed", "seed_light": "light", "seed_chip": "chip", "seed_noise": "noise"}
    for i, (row, rec) in enumerate(zip(rows, records)):
        for name in header:
            value, text = t[name][i], rec[name]
            if name in ds.parameter_keys:
                assert value == row["parameters"][name], name
                assert value == (text if isinstance(row["parameters"][name], str) else json.loads(text)), name
            elif name in seeds:
                assert value == row["seeds"][seeds[name]] == int(text), name
            elif name == "bytes" or name in SUMMARY_COLUMNS:
                known = row.get(name) if name == "bytes" else row.get("ground_truth", {}).get(name)
                if known is None:
                    assert math.isnan(value) and text == "" and row["status"] != "done", name
                else:
                    assert value == known == float(text), name
            elif name == "warnings":  # how many the sample's run gave (its metadata.json's)
                if row["status"] == "done":
                    assert value == len(row["warnings"]) == int(text), name
                    meta = json.loads((dataset_dir / row["folder"] / "metadata.json").read_text())
                    assert row["warnings"] == meta["warnings"] == ds.sample(i).warnings
                else:
                    assert math.isnan(value) and text == "" and "warnings" not in row, name
            elif name == "index":
                assert value == row["index"] == int(text) == i
            else:
                assert value == row.get(name, "") == text, name
    assert t["status"].tolist() == ["done", "done", "failed", "done"]
    assert t["camera.width_px"].tolist() == WIDTHS
    assert "invalid scene" in t["error"][2] and "16 x 500 sensor" in t["error"][2]
    part = ds.table(columns=["index", "hit_fraction"])
    assert list(part) == ["index", "hit_fraction"] and part["hit_fraction"][0] == 1.0
    with pytest.raises(KeyError, match="no column 'hit'"):
        ds.table(columns=["hit"])


def test_to_pandas(ds):
    pandas = pytest.importorskip("pandas")
    frame = ds.select(status="done").to_pandas()
    assert isinstance(frame, pandas.DataFrame) and list(frame.columns) == ds.columns
    assert frame["index"].tolist() == DONE and frame["camera.width_px"].tolist() == [1024, 1000, 1024]


def test_select_by_status_parameters_and_rows(ds):
    assert ds.select(status="done").indices.tolist() == DONE
    assert ds.select(status="failed").indices.tolist() == [2]
    assert ds.select(status=("failed", "stale")).indices.tolist() == [2]
    assert len(ds.select(status="missing")) == 0 and ds.select().indices.tolist() == [0, 1, 2, 3]
    assert ds.select(camera__width_px=1024).indices.tolist() == [0, 3]
    assert ds.select(**{"camera.width_px": 1000}).indices.tolist() == [1]
    assert ds.select(status="done", camera__width_px=16).indices.tolist() == []
    preset = ds.index[0]["parameters"]["sensor.preset"]
    expected = [r["index"] for r in ds.index if r["parameters"]["sensor.preset"] == preset]
    assert ds.select(sensor__preset=preset).indices.tolist() == expected
    power = ds.index[3]["parameters"]["laser.average_power_mW"]
    assert ds.select(**{"laser.average_power_mW": power}).indices.tolist() == [3]
    bright = ds.select(status="done", where=lambda r: r["ground_truth"]["laser_photons_per_pulse"] > 1.0)
    assert bright.indices.tolist() == [r["index"] for r in ds.index
                                       if r["status"] == "done" and r["ground_truth"]["laser_photons_per_pulse"] > 1.0]
    # Selections of selections, slices, positions and dataset indices.
    view = ds.select(status="done").select(camera__width_px=1024)
    assert view.indices.tolist() == [0, 3] and view[1].index == 3 and view.sample(3).index == 3
    assert ds[1:3].indices.tolist() == [1, 2] and [s.index for s in ds] == [0, 1, 2, 3]
    # The kinds of a selection's columns are the whole dataset's.
    assert view.table()["camera.width_px"].dtype == np.int64 and len(ds.select(status="missing").table()["scene"]) == 0
    with pytest.raises(KeyError, match="sample 1 is not in"):
        view.sample(1)
    # a position past the selection, or not a position, is said so (they were Python's bare "list index out of
    # range" and "list indices must be integers"); so is a status that is no text
    with pytest.raises(IndexError, match=r"ds\[2\] is past this selection of 2 samples \(positions 0 to 1; sample\(index\)"):
        view[2]
    assert view[-2].index == 0
    with pytest.raises(TypeError, match=r"ds\['a'\]; expected a position"):
        view["a"]
    with pytest.raises(TypeError, match="select: status=5; expected one of done"):
        ds.select(status=5)
    # positions and statuses as NumPy gives them (0-d integers, arrays)
    assert view[np.int64(1)].index == view[np.array(1)].index == 3
    assert ds.select(status=np.array(["done"])).indices.tolist() == ds.select(status="done").indices.tolist()
    # NumPy values as the Python ones (an array matched nothing, silently)
    assert ds.select(camera__width_px=np.int64(1000)).indices.tolist() == [1]
    assert ds.select(camera__width_px=np.array(1024)).indices.tolist() == [0, 3]
    crops = {0: [0, 0, 8, 8], 1: [8, 0, 8, 8]}
    spec = dict(ds.spec, grid={"camera.crop": list(crops.values())})
    rows = [dict(r, parameters=dict(r["parameters"], **{"camera.crop": crops[r["index"] % 2]})) for r in ds.index]
    arrays = spadgen.Dataset(ds.path, _spec=spec, _rows=rows, _all=rows)
    assert arrays.select(camera__crop=np.array([8, 0, 8, 8])).indices.tolist() == [1, 3]
    assert arrays.select(camera__crop=(0, 0, 8, 8)).indices.tolist() == [0, 2]
    assert arrays.select(camera__crop=np.array([8, 0, 8])).indices.tolist() == []
    with pytest.raises(ValueError, match="unknown status"):
        ds.select(status="ok")
    with pytest.raises(ValueError, match="no parameter 'laser_power'"):
        ds.select(laser_power=1)
    assert set(STATUSES) == {"done", "failed", "stale", "missing", "damaged"}


def test_samples_are_their_folders_runs(ds, dataset_dir):
    for sample in ds.select(status="done"):
        row = ds.index[sample.index]
        assert sample.folder == str(dataset_dir / row["folder"]) and sample.status == "done"
        assert sample.parameters == row["parameters"] and sample.seeds == row["seeds"]
        assert sample.ground_truth == row["ground_truth"] and sample.error is None
        assert sample.parameters["camera.width_px"] == WIDTHS[sample.index]
        reference = spadgen.open_run(dataset_dir / row["folder"])
        run = sample.run
        assert run is sample.run  # opened once
        assert run.metadata == reference.metadata and run.metadata["dataset"]["index"] == sample.index
        assert run.metadata["dataset"]["parameters"] == sample.parameters
        np.testing.assert_array_equal(run.counts, reference.counts)
        np.testing.assert_array_equal(run.detection_rate, reference.detection_rate)
        np.testing.assert_array_equal(run.depth(), reference.depth())
        assert len(sample.repeats) == 1 and sample.repeat_folders == [str(dataset_dir / row["repeats"][0])]
        again = spadgen.open_run(dataset_dir / row["repeats"][0])
        np.testing.assert_array_equal(sample.repeats[0].counts, again.counts)
        assert [r.path for r in sample.realisations] == [sample.folder] + sample.repeat_folders
        assert sample.ground_truth["hit_fraction"] == float(run.hit().mean())


def test_realisations_differ_in_counts_and_share_the_ground_truth(ds):
    for sample in ds.select(status="done"):
        first, second = sample.realisations
        assert second.metadata["seeds"]["noise"] == first.metadata["seeds"]["noise"] + 1 == sample.seeds["noise"] + 1
        assert second.metadata["dataset"]["repeat"] == 1 and first.metadata["dataset"]["repeat"] == 0
        assert not np.array_equal(first.counts, second.counts)
        np.testing.assert_array_equal(first.detection_rate, second.detection_rate)
        np.testing.assert_array_equal(first.laser["photons_per_pulse"], second.laser["photons_per_pulse"])
        np.testing.assert_array_equal(first.layers().range, second.layers().range)
        np.testing.assert_array_equal(first.depth(), second.depth())


def test_errors_name_the_folder(ds, dataset_dir, tmp_path, sweep_run, spadgen_bin):
    failed = ds.sample(2)
    assert failed.status == "failed" and "16 x 500 sensor" in failed.error
    with pytest.raises(spadgen.SampleNotDoneError, match=r"(?s)sample 2 \(samples/000002\) failed.*16 x 500 sensor"):
        failed.run
    with pytest.raises(spadgen.SampleNotDoneError, match="sample 2"):
        failed.repeats
    missing = spadgen.Sample(ds, dict(ds.index[0], status="missing"))
    with pytest.raises(spadgen.SampleNotDoneError, match=f"{dataset_dir}: sample 0 .* is missing"):
        missing.run
    # An index read before the sample was generated again (or one a stopped run left behind).
    moved = spadgen.Sample(ds, dict(ds.index[0], sample_hash="0123456789abcdef"))
    with pytest.raises(spadgen.SampleNotDoneError, match=r"was generated again since; open the dataset again \(spadgen.open_dataset\)"):
        moved.run
    # A done sample whose folder was removed after the index was written: said so with the remedy, as evaluate
    # says it (it was a bare "no such folder", also inside a DataLoader's workers).
    gone = spadgen.Sample(ds, dict(ds.index[0], folder="samples/999999"))
    with pytest.raises(spadgen.SampleNotDoneError, match=r"samples/999999: .*index.jsonl lists realisation 0 of sample 0 "
                                                          r"done \(hash [0-9a-f]{16}\), and its folder does not exist.*"
                                                          r"`spadgen dataset run` brings the index up to date"):
        gone.run
    with pytest.raises(FileNotFoundError, match=f"{tmp_path / 'nothing'}: not a spadgen dataset folder.*no such folder"):
        spadgen.open_dataset(tmp_path / "nothing")
    with pytest.raises(FileNotFoundError, match="it is a run folder: spadgen.open_run reads it"):
        spadgen.open_dataset(sweep_run)
    (tmp_path / "unfinished").mkdir()
    (tmp_path / "unfinished" / "dataset.json").write_text((dataset_dir / "dataset.json").read_text())
    with pytest.raises(FileNotFoundError, match="without index.jsonl: the first `spadgen dataset run` into it was killed"):
        spadgen.open_dataset(tmp_path / "unfinished")
    # A damaged dataset.json: the remedy is what `spadgen dataset run` accepts (it refuses such a folder: "run the
    # dataset again" was said), checked against the program's own refusal.
    (tmp_path / "unfinished" / "index.jsonl").write_text((dataset_dir / "index.jsonl").read_text())
    remedy = ("it says which dataset file the folder holds, and `spadgen dataset run` refuses the folder without it: "
              "restore it, or generate the dataset into another folder")
    for text, says in (('{"samples": 4', "not valid JSON .*damaged afterwards; "), ("[1, 2]", "JSON, but not an object .*")):
        (tmp_path / "unfinished" / "dataset.json").write_text(text)
        with pytest.raises(ValueError, match=f"{tmp_path / 'unfinished' / 'dataset.json'}: {says}{remedy}"):
            spadgen.open_dataset(tmp_path / "unfinished")
        if not (tmp_path / "scenes").exists():
            (tmp_path / "scenes").symlink_to(SCENES)
        (tmp_path / "d.json").write_text(DATASET)
        r = subprocess.run([spadgen_bin, "dataset", "run", str(tmp_path / "d.json"), "-o", str(tmp_path / "unfinished"), "-q"],
                           capture_output=True, text=True)
        assert r.returncode != 0 and "dataset.json is damaged" in r.stderr and "restore it" in r.stderr, r.stderr


def test_a_damaged_samples_remedy_names_its_dataset_folder(dataset_dir, tmp_path):
    """A done sample's file lost: the remedy is the dataset run into that dataset's folder, named (it said
    `-o DIR`, the folder known)."""
    import shutil
    copy = tmp_path / "ds"
    shutil.copytree(dataset_dir, copy, symlinks=True)
    os.remove(copy / "samples" / "000001_r01" / "counts.npy")
    with pytest.raises(FileNotFoundError, match=f"counts.npy: listed in .* but missing: restore it, or run `spadgen dataset "
                                                f"run .*d.json -o {copy}` on its dataset folder again"):
        spadgen.open_dataset(copy).sample(1).repeats[0].counts
    # a sample's folder alone (outside a dataset folder): DIR, as the folder is not known
    shutil.copytree(copy / "samples" / "000001_r01", tmp_path / "alone")
    with pytest.raises(FileNotFoundError, match=r"-o DIR` on its dataset folder again"):
        spadgen.open_run(tmp_path / "alone").counts


def test_a_damaged_index_is_refused_naming_its_row(dataset_dir, tmp_path):
    """index.jsonl edited after `spadgen dataset run` wrote it: a row copied again (its sample was read, and
    trained on, twice), rows of other types than spadgen writes (they were TypeError, AttributeError or
    KeyError from wherever they were read): a ValueError naming the file and the row, as `spadgen evaluate`."""
    rows = (dataset_dir / "index.jsonl").read_text().splitlines()
    copy = tmp_path / "ds"
    copy.mkdir()
    (copy / "dataset.json").write_text((dataset_dir / "dataset.json").read_text())
    index = copy / "index.jsonl"

    def refused(lines, says, row=2):
        index.write_text("\n".join(lines) + "\n")
        with pytest.raises(ValueError, match=f"{index} row {row}: " + says):
            spadgen.open_dataset(copy)

    refused(rows + [rows[0]], "lists sample 0 again \\(row 1 lists it\\); the index was damaged", len(rows) + 1)
    twin = dict(json.loads(rows[0]), index=len(rows))  # another index, the same folder
    refused(rows + [json.dumps(twin)], "lists the folder samples/000000 again \\(row 1 lists it\\)", len(rows) + 1)
    for key, value, says in (("index", "1", 'expected an integer "index"'), ("status", 5, 'expected a string "status"'),
                             ("folder", 5, 'expected a string "folder"'), ("status", "great", 'status "great" is not one of'),
                             ("parameters", [1], 'expected an object "parameters"'),
                             ("repeats", "x", 'expected a list of folders "repeats"'),
                             ("folder", "../../elsewhere", "lists the folder ../../elsewhere, not a sample folder")):
        edited = list(rows)
        edited[1] = json.dumps(dict(json.loads(rows[1]), **{key: value}))
        refused(edited, says)
    refused([rows[0], "[1, 2]"] + rows[2:], "not a JSON object")
    index.write_text("\n".join(rows) + "\n")
    assert len(spadgen.open_dataset(copy)) == len(rows)


def test_an_index_cut_short_or_without_a_row_is_refused_unless_a_run_is_on(dataset_dir, spadgen_bin, tmp_path):
    """index.jsonl holds a row per sample of dataset.json, in index order: one cut short on a line boundary (a full
    disk, a copy) or without a row was read as a smaller dataset without a word, where `spadgen dataset status`
    calls it damaged. While a dataset run is on the folder (dataset.json is then the running one's, the index the
    last finished run's) the difference is a warning; the run's presence is the program's own test of it, checked
    here against `spadgen dataset status`."""
    import fcntl
    import os
    import struct
    import warnings
    rows = (dataset_dir / "index.jsonl").read_text().splitlines()
    assert len(rows) == 4
    copy = tmp_path / "ds"
    copy.mkdir()
    (copy / "dataset.json").write_text((dataset_dir / "dataset.json").read_text())
    index = copy / "index.jsonl"
    # (fewer rows: most often a run that raised "samples" killed before it wrote the index; both remedies said)
    short = (f"{index} has 2 rows for the 4 samples of {copy / 'dataset.json'}: a `spadgen dataset run` that changed "
             "the dataset's samples was killed before it wrote the index, or the index was cut short after it was "
             "written; `spadgen dataset run` with the dataset file generates what is left and writes the index again "
             r"\(run with the dataset file the folder held before, it writes only the index and the card\)")
    for lines, says in ((rows[:2], short), ([], f"{index} has 0 rows for the 4 samples"),
                        (rows[:2] + rows[3:], f"{index} row 3: lists sample 3 where sample 2 belongs"),
                        ([rows[1], rows[0]] + rows[2:], f"{index} row 1: lists sample 1 where sample 0 belongs"),
                        # the last row cut inside (a JSON error per line said "line 1" of every row)
                        (rows[:3] + [rows[3][:40]], f"{index} row 4: not valid JSON \\(.* at column .*damaged afterwards")):
        index.write_text("".join(line + "\n" for line in lines))
        with pytest.raises(ValueError, match=says):
            spadgen.open_dataset(copy)
    # "samples": null is one sample per grid cell (3 widths x 1 scene): the 4 rows are one too many
    spec = json.loads((dataset_dir / "dataset.json").read_text())
    (copy / "dataset.json").write_text(json.dumps(dict(spec, samples=None)))
    index.write_text("".join(line + "\n" for line in rows))
    with pytest.raises(ValueError, match=f"{index} has 4 rows for the 3 samples of {copy / 'dataset.json'}: the "
                                         "index was added to, or dataset.json edited, after they were written; "
                                         "`spadgen dataset status` names what is wrong"):
        spadgen.open_dataset(copy)
    (copy / "dataset.json").write_text(json.dumps(spec))
    assert len(spadgen.open_dataset(copy)) == 4
    # a run on the folder: its presence lock held as a run holds it (a shared OFD lock on byte 0)
    index.write_text("".join(line + "\n" for line in rows[:2]))
    fd = os.open(copy / ".dataset.runs", os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.fcntl(fd, fcntl.F_OFD_SETLK, struct.pack("hhqqi4x", fcntl.F_RDLCK, os.SEEK_SET, 0, 1, 0))
        status = subprocess.run([spadgen_bin, "dataset", "status", str(copy)], capture_output=True, text=True)
        assert "a dataset run is on the folder now" in status.stdout + status.stderr, status.stdout + status.stderr
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            held = spadgen.open_dataset(copy)
        assert held.indices.tolist() == [0, 1]
        assert [str(w.message) for w in said] == [f"{index} has 2 rows for the 4 samples of {copy / 'dataset.json'}: a "
                                                  "`spadgen dataset run` is on the folder now, and the last run to end "
                                                  "writes the index; this Dataset holds the rows written so far"]
    finally:
        os.close(fd)
    with pytest.raises(ValueError, match=short):
        spadgen.open_dataset(copy)
    # the card, when lost, is said with the remedy
    with pytest.raises(FileNotFoundError, match=f"{copy / 'dataset.md'}: missing .*run the dataset again to write it"):
        held.card


def test_a_row_of_other_parameters_or_seeds_than_its_folder_is_refused_when_opened(dataset_dir, tmp_path):
    """A done sample's row edited to other parameters or seeds (select() returned it by values it was not made
    with; an adversarial tester's find): opening its run says so, as `spadgen dataset status` does."""
    import shutil
    copy = tmp_path / "ds"
    shutil.copytree(dataset_dir, copy)
    rows = [json.loads(line) for line in (copy / "index.jsonl").read_text().splitlines()]
    i = next(k for k, r in enumerate(rows) if r["status"] == "done")
    assert spadgen.open_dataset(copy).sample(i).run is not None
    key = next(iter(rows[i]["parameters"]))
    for field, edit in (("parameters", {key: 99}), ("seeds", {"chip": 12345})):
        edited = [dict(r) for r in rows]
        edited[i] = dict(rows[i], **{field: dict(rows[i][field], **edit)})
        (copy / "index.jsonl").write_text("".join(json.dumps(r) + "\n" for r in edited))
        sample = spadgen.open_dataset(copy).sample(i)
        with pytest.raises(ValueError, match=f"{copy / 'index.jsonl'}: sample {i}'s {field} .* are not its folder's "
                                             ".*index.jsonl was edited or damaged"):
            sample.run
    (copy / "index.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    assert len(spadgen.open_dataset(copy).sample(i).realisations) >= 1


# ---- spadgen.torchdata.DatasetSamples --------------------------------------------------------------------------

def test_dataset_samples_layout_values_and_length(ds, dataset_dir):
    torch = pytest.importorskip("torch")
    from spadgen.torchdata import FIELDS, DatasetSamples, RunDataset

    run = ds.sample(0).run
    K, N, H, W = run.K, run.frames_per_k, run.height, run.width
    from test_torch import expected_layout
    layout = expected_layout(K, N, 3, H, W, int(run.metadata["ground_truth_objects"]))
    del layout["frames"]  # the dataset's runs did not write frames.npy
    layout.update({"sample": ((), torch.int64), "repeat": ((), torch.int64), "parameters": ((3,), torch.float32)})
    with pytest.raises(ValueError, match="needs frames, which this run did not write"):
        DatasetSamples(dataset_dir, fields=FIELDS)
    fields = tuple(f for f in FIELDS if f != "frames")
    samples = DatasetSamples(dataset_dir, fields=fields)
    assert len(samples) == 3 * 2  # done samples x realisations
    assert samples.parameter_names == NUMERIC
    assert samples.realisations == [(0, 0), (0, 1), (1, 0), (1, 1), (3, 0), (3, 1)]
    plain = RunDataset(samples.paths, fields=fields)  # the same loading: the same tensors
    table = ds.table()
    for j in range(len(samples)):
        item = samples[j]
        assert set(item) == set(layout)
        for key, (shape, dtype) in layout.items():
            assert tuple(item[key].shape) == shape and item[key].dtype == dtype, key
        index, repeat = samples.realisations[j]
        assert (int(item["sample"]), int(item["repeat"]), int(item["run"])) == (index, repeat, j)
        realisation = ds.sample(index).realisations[repeat]
        np.testing.assert_array_equal(item["counts"].numpy(), realisation.counts)
        np.testing.assert_array_equal(item["depth"][0].numpy(), realisation.depth())
        expected = np.array([table[k][index] for k in NUMERIC], np.float32)
        np.testing.assert_array_equal(item["parameters"].numpy(), expected)
        for key, value in plain[j].items():
            assert torch.equal(item[key], value), key

    patches = DatasetSamples(ds, patch_size=(10, 12), repeats="first")
    assert len(patches) == 3 * (20 // 10) * (24 // 12)
    item = patches[5]  # sample 1, its second patch: row 0, column 1
    assert (int(item["sample"]), int(item["repeat"])) == (1, 0) and item["origin"].tolist() == [12, 0]
    np.testing.assert_array_equal(item["counts"].numpy(), ds.sample(1).run.counts[:, 0:10, 12:24])
    assert len(DatasetSamples(ds, patch_size=10)) == 3 * 2 * 4
    assert [s for s, _ in DatasetSamples(ds.select(camera__width_px=1024)).realisations] == [0, 0, 3, 3]


def test_dataset_samples_in_pairs_of_realisations(ds, dataset_dir, spadgen_bin, tmp_path):
    """repeats="pairs" (Noise2Noise): each realisation's counts with the next realisation's of the same patch,
    read on their own from the realisations' folders; a sample of one realisation is refused."""
    pytest.importorskip("torch")
    from spadgen.torchdata import DatasetSamples

    pairs = DatasetSamples(ds, patch_size=(10, 12), repeats="pairs")
    assert len(pairs) == len(DatasetSamples(ds, patch_size=(10, 12))) == 3 * 2 * 4
    for j in range(len(pairs)):
        item = pairs[j]
        index, repeat = int(item["sample"]), int(item["repeat"])
        x, y = item["origin"].tolist()
        assert int(item["repeat_pair"]) == 1 - repeat
        folder = dataset_dir / "samples" / (f"{index:06d}" if repeat == 1 else f"{index:06d}_r01")
        expected = np.load(folder / "counts.npy")[:, y:y + 10, x:x + 12].astype(np.float32)
        np.testing.assert_array_equal(item["counts_pair"].numpy(), expected)
        assert not np.array_equal(item["counts_pair"].numpy(), item["counts"].numpy())  # independent noise
    # a dataset of one realisation per sample
    (tmp_path / "scenes").symlink_to(SCENES)
    (tmp_path / "one.json").write_text(DATASET.replace('"samples": 4', '"samples": 1').replace('"repeats": 2', '"repeats": 1'))
    subprocess.run([spadgen_bin, "dataset", "run", str(tmp_path / "one.json"), "-o", str(tmp_path / "one"), "-q"], check=True)
    with pytest.raises(ValueError, match=r"sample 0 has 1 realisation\(s\).*repeats='pairs' pairs two realisations.*"
                                         r"a dataset of repeats 1 does not keep unless it sets outputs.light: its samples "
                                         r"are rendered again\)"):
        DatasetSamples(tmp_path / "one", repeats="pairs")
    # ... as `spadgen dataset plan` of repeats 2 into it says: every sample rendered again, none only sensed
    (tmp_path / "two.json").write_text(DATASET.replace('"samples": 4', '"samples": 1'))
    plan = subprocess.run([spadgen_bin, "dataset", "plan", str(tmp_path / "two.json"), "-o", str(tmp_path / "one")],
                          capture_output=True, text=True, check=True).stdout
    assert f"left to generate in {tmp_path / 'one'}: 1 sample, disk" in plan, plan


def test_dataset_samples_refuse_what_has_no_run(ds, dataset_dir):
    pytest.importorskip("torch")
    from spadgen.torchdata import DatasetSamples

    with pytest.raises(ValueError, match=r"samples \[2\] are not done"):
        DatasetSamples(dataset_dir, status=None)
    with pytest.raises(ValueError, match="no sample to load with status='missing'"):
        DatasetSamples(dataset_dir, status="missing")
    with pytest.raises(ValueError, match="repeats must be"):
        DatasetSamples(dataset_dir, repeats=2)


@pytest.mark.parametrize("workers", [0, 2])
def test_dataset_samples_in_a_data_loader(dataset_dir, workers):
    torch = pytest.importorskip("torch")
    from spadgen.torchdata import DatasetSamples

    samples = DatasetSamples(dataset_dir, patch_size=10)
    loader = torch.utils.data.DataLoader(samples, batch_size=2, num_workers=workers)
    batches = list(loader)
    assert len(batches) == len(samples) // 2 == 12
    K = samples[0]["counts"].shape[0]
    for b in batches:
        assert tuple(b["counts"].shape) == (2, K, 10, 10) and tuple(b["parameters"].shape) == (2, 3)
        assert b["sample"].dtype == torch.int64 and b["parameters"].dtype == torch.float32
    order = [(s, r) for b in batches for s, r in zip(b["sample"].tolist(), b["repeat"].tolist())]
    assert order == [pair for pair in samples.realisations for _ in range(4)]
    np.testing.assert_array_equal(torch.cat([b["counts"] for b in batches]).numpy(),
                                  np.stack([samples[j]["counts"].numpy() for j in range(len(samples))]))


def test_the_cards_snippet_runs_in_the_folder(ds, dataset_dir, monkeypatch):
    # dataset.md's "Reading it" (written by the C++ side) must stay true to this package.
    code = ds.card.split("## Reading it", 1)[1].split("```python\n", 1)[1].split("```", 1)[0]
    monkeypatch.chdir(dataset_dir)
    namespace = {}
    exec(compile(code, "dataset.md", "exec"), namespace)
    assert namespace["rows"] == ds.index and namespace["ds"].indices.tolist() == [0, 1, 2, 3]
    assert namespace["run"].metadata["dataset"]["index"] == 0 and namespace["run"].counts.shape == (101, 20, 24)


def test_a_samples_warnings(spadgen_bin, tmp_path):
    """Sample.warnings and the table's warnings column hold what each sample's run warned about (here frames
    longer than the camera's in sample 1 only), as its metadata.json and index.csv have them."""
    (tmp_path / "d.json").write_text(json.dumps({
        "seed": 1, "scenes": [str(SOURCE / "scenes" / "paper" / "multi_object.json")], "samples": 2,
        "set": {"render.samples_per_pixel": 2, "camera.crop": [496, 236, 8, 4], "outputs.previews": False},
        "grid": {"acquisition.cycles_per_frame": [1600, 1915]}}))
    subprocess.run([spadgen_bin, "dataset", "run", str(tmp_path / "d.json"), "-o", str(tmp_path / "out"), "-q"], check=True,
                   capture_output=True)
    ds = spadgen.open_dataset(tmp_path / "out")
    quiet, warned = ds.sample(0), ds.sample(1)
    assert quiet.warnings == [] and len(warned.warnings) == 1 and "1915 laser cycles" in warned.warnings[0]
    assert warned.warnings == warned.run.metadata["warnings"]
    assert ds.table(columns=["warnings"])["warnings"].tolist() == [0.0, 1.0]
    with open(tmp_path / "out" / "index.csv", newline="") as f:
        assert [r["warnings"] for r in csv.DictReader(f)] == ["0", "1"]


def test_a_dataset_folder_without_its_index_says_whether_its_first_run_is_running(spadgen_bin, dataset_dir, tmp_path):
    """A first run still on the folder (its presence lock held: here taken as a run takes it, a shared
    open-file-description lock on byte 0 of .dataset.runs) is waited for, not run again; a killed one is run
    again. Said alike by open_dataset and spadgen evaluate (both said "still running or was killed ... run it
    again to finish"; an auditor's find)."""
    import fcntl
    import re
    import struct
    folder = tmp_path / "unfinished"
    folder.mkdir()
    (folder / "dataset.json").write_text((dataset_dir / "dataset.json").read_text())

    def says(what):
        with pytest.raises(FileNotFoundError, match=re.escape(f"without index.jsonl: {what}")):
            spadgen.open_dataset(folder)
        r = subprocess.run([spadgen_bin, "evaluate", str(folder), "-q"], capture_output=True, text=True)
        assert r.returncode == 1, r.stderr
        assert f"without index.jsonl: {what}" in r.stderr, r.stderr

    says("the first `spadgen dataset run` into it was killed")
    fd = os.open(folder / ".dataset.runs", os.O_RDWR | os.O_CREAT, 0o666)
    try:
        fcntl.fcntl(fd, fcntl.F_OFD_SETLK, struct.pack("hhqqi4x", fcntl.F_RDLCK, os.SEEK_SET, 0, 1, 0))
        says("the first `spadgen dataset run` into it is still running (the last run on the folder to end writes the "
             "index); wait for it to finish")
    finally:
        os.close(fd)
    says("the first `spadgen dataset run` into it was killed")


def test_a_damaged_dataset_folder_is_named_by_every_reader(dataset_dir, tmp_path):
    """dataset.json, a row of index.jsonl or a done sample's metadata.json damaged at random places (120 cases from
    a fixed seed, after the soak's finds), then the dataset read whole (its table, each sample's run and counts):
    a ValueError, OSError or SampleNotDoneError naming what is wrong, never a TypeError, KeyError or
    OverflowError from wherever it was read (a soak of 1,500 cases found a "random" of null, a seed removed or of
    another type, and a row's warnings of null read so)."""
    import random
    import shutil
    from conftest import damage_at, damage_json
    from spadgen.dataset import SampleNotDoneError
    out = tmp_path / "out"
    shutil.copytree(dataset_dir, out, symlinks=True)
    sample_meta = out / "samples" / "000000" / "metadata.json"
    originals = {p: p.read_text() for p in (out / "dataset.json", out / "index.jsonl", sample_meta)}
    rng = random.Random(20261207)
    found = [("dataset.json", ("random",), None), ("dataset.json", ("grid",), 1e308), ("index.jsonl", ("seeds", "chip"), ...),
             ("index.jsonl", ("seeds", "seed"), 1e308), ("index.jsonl", ("seeds", "light"), {}), ("index.jsonl", ("warnings",), None),
             ("index.jsonl", ("ground_truth", "range_max_m"), {})]
    named = 0
    for c in range(len(found) + 120):
        for p, text in originals.items():
            p.write_text(text)
        if c < len(found):
            name, at, value = found[c]
        else:
            name = ("dataset.json", "index.jsonl", "metadata.json")[rng.randrange(3)]
        path = sample_meta if name == "metadata.json" else out / name
        if name == "index.jsonl":
            rows = originals[path].splitlines()
            r = 0 if c < len(found) else rng.randrange(len(rows))
            doc = json.loads(rows[r])
        else:
            doc = json.loads(originals[path])
        what = f"{name} " + (damage_at(doc, at, value) if c < len(found) else damage_json(doc, rng))
        if name == "index.jsonl":
            rows[r] = json.dumps(doc)
            path.write_text("\n".join(rows) + "\n")
        else:
            path.write_text(json.dumps(doc))
        try:
            ds = spadgen.open_dataset(out)
            ds.status_counts()
            ds.table()
            repr(ds), ds.parameter_keys, ds.numeric_parameter_keys, ds.columns
            for i in ds.select(status="done").indices:
                np.asarray(ds.sample(int(i)).run.counts)
        except (ValueError, OSError, SampleNotDoneError):
            named += 1
        except Exception as e:
            raise AssertionError(f"{what}: {e!r}") from e
    for p, text in originals.items():
        p.write_text(text)
    assert named > 30, "the damage is read, and named, not ignored wholesale"
