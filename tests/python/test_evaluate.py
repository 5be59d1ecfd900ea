"""spadgen.evaluate: detections given from Python (arrays, a mapping per sample, files) scored by the program,
against detections made from the ground truth itself (perfect, shifted, none)."""
import os
import subprocess

import numpy as np
import pytest

import spadgen
from spadgen.evaluate import EvaluateError


def perfect_ranges(run):
    """Every object's range along each pixel's ray as detections (H, W, J), NaN in unused slots."""
    slots = run.object_slots()
    r = np.where(slots.id >= 0, slots.range, np.nan).astype(np.float32)
    return np.moveaxis(r, 0, -1)


def test_perfect_shifted_and_no_detections(sweep_run, spadgen_bin, tmp_path):
    run = spadgen.open_run(sweep_run)
    truth = perfect_ranges(run)
    objects = int(np.count_nonzero(~np.isnan(truth)))
    assert objects > run.width * run.height  # the plate's pixels hold two objects
    m = spadgen.evaluate(run.path, truth, out=tmp_path / "perfect", program=spadgen_bin)
    assert m["objects"]["objects"] == objects and m["objects"]["found"] == objects
    assert m["detections"]["false"] == 0 and m["detections"]["total"] == objects
    assert abs(m["range_error"]["bias_mm"]) < 1e-9 and m["range_error"]["rms_mm"] < 1e-9  # (the unfolding in double)
    assert m["detections_source"]["file"].endswith("detections.npy")
    assert not os.path.exists(m["detections_source"]["file"])  # the temporary file is gone
    # 10 mm too far: every object found, the bias the shift (float32 ranges: within 1e-3 mm)
    # (the Run itself, as RunDataset takes one: it was a bare TypeError)
    m = spadgen.evaluate(run, truth + np.float32(0.01), out=tmp_path / "shifted", program=spadgen_bin)
    assert m["run"] == run.path
    assert m["objects"]["found"] == objects
    assert m["range_error"]["bias_mm"] == pytest.approx(10.0, abs=1e-3)
    assert m["range_error"]["rms_mm"] == pytest.approx(10.0, abs=1e-3)
    # beyond the tolerance (50 mm): nothing found, every detection false
    m = spadgen.evaluate(run.path, truth + np.float32(0.06), out=tmp_path / "far", tolerance_m=0.05, program=spadgen_bin)
    assert m["objects"]["found"] == 0 and m["detections"]["false"] == objects
    m = spadgen.evaluate(run.path, np.full_like(truth, np.nan), out=tmp_path / "none", program=spadgen_bin)
    assert m["objects"]["found"] == 0 and m["detections"]["total"] == 0
    # nothing matched: the error statistics' keys are there, null (bias_mm was missing: a KeyError for readers)
    assert m["range_error"] == {"count": 0, "bias_mm": None, "rms_mm": None, "std_mm": None, "abs_p50_mm": None,
                                "abs_p90_mm": None, "abs_p99_mm": None}
    assert all(o["range_error"]["bias_mm"] is None for o in m["by_object"])


def test_the_detector_and_the_programs_refusals(sweep_run, spadgen_bin, tmp_path, monkeypatch):
    run = spadgen.open_run(sweep_run)
    m = spadgen.evaluate(run.path, out=tmp_path / "edges", program=spadgen_bin)
    assert m["detections_source"]["computed"] is True
    assert 0 < m["objects"]["found"] <= m["objects"]["objects"]
    with pytest.raises(EvaluateError, match="--tolerance-m") as e:
        spadgen.evaluate(run.path, tolerance_m=-1, out=tmp_path / "bad", program=spadgen_bin)
    assert e.value.returncode == 1 and not (tmp_path / "bad").exists()
    assert str(e.value).endswith("[spadgen.evaluate: --tolerance-m is tolerance_m=]"), str(e.value)  # the flag as the argument
    # values the program refuses, named at their place in the array (its message named a temporary file already gone)
    bad = np.full((run.height, run.width, 2), np.nan, np.float32)
    bad[1, 2, 1], bad[3, 0, 0] = -1.0, np.inf
    with pytest.raises(ValueError, match=r"detections: \[1, 2, 1\] \(y, x, slot\) is -1.0, and 2 values in all are infinite or "
                                         "negative; expected ranges in metres >= 0, NaN where there is none"):
        spadgen.evaluate(run.path, bad, out=tmp_path / "t", program=spadgen_bin)
    with pytest.raises(ValueError, match=r"expected a float array \(H, W, M\)"):
        spadgen.evaluate(run.path, np.zeros((run.height, run.width)), program=spadgen_bin)
    with pytest.raises(ValueError, match=rf"shape \({run.width}, {run.height}, 2\), expected \({run.height}, {run.width}, M\)"):
        spadgen.evaluate(run.path, np.full((run.width, run.height, 2), np.nan, np.float32), out=tmp_path / "t",
                         program=spadgen_bin)
    with pytest.raises(ValueError, match=r"np.moveaxis\(a, 0, -1\)"):  # (M, H, W), as torch's object_range is
        spadgen.evaluate(run.path, np.full((2, run.height, run.width), np.nan, np.float32), program=spadgen_bin)
    with pytest.raises(ValueError, match="not a dataset folder"):
        spadgen.evaluate(run.path, {"000000": perfect_ranges(run)}, program=spadgen_bin)
    # What the program refuses with detections given, said in the arguments' names (its message named its flags
    # and a temporary .npy already gone), checked against the program's own refusal
    ranges = perfect_ranges(run)
    with pytest.raises(ValueError, match="min_score: arrays of ranges hold no scores"):
        spadgen.evaluate(run, ranges, min_score=10, out=tmp_path / "s", program=spadgen_bin)
    np.save(tmp_path / "ranges.npy", ranges)
    with pytest.raises(EvaluateError, match="--min-score: a .npy of ranges holds no scores"):
        spadgen.evaluate(run, tmp_path / "ranges.npy", min_score=10, out=tmp_path / "s", program=spadgen_bin)
    for given in (ranges, tmp_path / "ranges.npy"):
        for kwargs in ({"noise_free": True}, {"detector": "paper"}):
            with pytest.raises(ValueError, match="with detections given, leave them out"):
                spadgen.evaluate(run, given, out=tmp_path / "s", program=spadgen_bin, **kwargs)
    r = subprocess.run([spadgen_bin, "evaluate", str(run.path), "--detections", str(tmp_path / "ranges.npy"), "--noise-free",
                        "-o", str(tmp_path / "s")], capture_output=True, text=True)
    assert r.returncode == 1 and "--detections excludes --noise-free" in r.stderr, r.stderr
    assert not (tmp_path / "s").exists()
    with pytest.raises(FileNotFoundError, match="no such executable file"):
        spadgen.evaluate(run.path, program=tmp_path / "no_such_program")
    (tmp_path / "not_executable").write_text("")
    monkeypatch.setenv("SPADGEN_BIN", str(tmp_path / "not_executable"))  # named, so not passed over
    with pytest.raises(FileNotFoundError, match=r"not_executable \(\$SPADGEN_BIN\): no such executable file"):
        spadgen.evaluate(run.path)


def test_a_dataset_scored_from_a_mapping_and_from_files(dataset_dir, spadgen_bin, tmp_path):
    ds = spadgen.open_dataset(dataset_dir)
    folders = [f for s in ds.select(status="done") for f in [s.folder] + s.repeat_folders]
    assert len(folders) == 6  # 3 done samples, 2 realisations each
    truth = {os.path.basename(f): perfect_ranges(spadgen.open_run(f)) for f in folders}
    objects = sum(int(np.count_nonzero(~np.isnan(t))) for t in truth.values())
    m = spadgen.evaluate(dataset_dir, truth, out=tmp_path / "mapping", program=spadgen_bin)
    assert m["objects"]["objects"] == objects and m["objects"]["found"] == objects
    assert sorted(s["sample"] for s in m["samples"]) == sorted(truth)
    for s in m["samples"]:
        assert s["metrics"]["objects"]["found"] == int(np.count_nonzero(~np.isnan(truth[s["sample"]])))
    # the same as files named with {sample}
    preds = tmp_path / "preds"
    preds.mkdir()
    for name, t in truth.items():
        np.save(preds / f"{name}.npy", t + np.float32(0.002))
    m = spadgen.evaluate(dataset_dir, str(preds / "{sample}.npy"), out=tmp_path / "files", program=spadgen_bin)
    assert m["objects"]["found"] == objects and m["range_error"]["bias_mm"] == pytest.approx(2.0, abs=1e-3)
    # a sample without detections is named by the program; a name that is no done sample by the package
    partial = dict(truth)
    del partial[sorted(partial)[0]]
    with pytest.raises(ValueError, match=f"no detections for 1 of the 6 done sample folders of .*, first '{sorted(truth)[0]}'"):
        spadgen.evaluate(dataset_dir, partial, out=tmp_path / "partial", program=spadgen_bin)
    assert not (tmp_path / "partial").exists()
    with pytest.raises(ValueError, match="is a dataset folder: give its detections as a mapping"):
        spadgen.evaluate(dataset_dir, truth[sorted(truth)[0]], program=spadgen_bin)
    # the program's check, through files: a sample without one is named
    os.remove(preds / f"{sorted(truth)[0]}.npy")
    with pytest.raises(EvaluateError, match="1 of 6 done sample folders have no detections file"):
        spadgen.evaluate(dataset_dir, str(preds / "{sample}.npy"), out=tmp_path / "partial", program=spadgen_bin)
    # a selection of the dataset (a validation split): its samples only, its arrays only
    val = ds.select(where=lambda row: row["index"] == 3)
    picked = {k: v for k, v in truth.items() if k.startswith("000003")}
    m = spadgen.evaluate(val, picked, out=tmp_path / "val", program=spadgen_bin)
    assert m["selection"] == [[3, 3]] and sorted(s["sample"] for s in m["samples"]) == sorted(picked)
    assert m["objects"]["found"] == m["objects"]["objects"] > 0
    # detections of a done sample outside the selection: said so (it was "no done sample folder")
    other = next(k for k in sorted(truth) if not k.startswith("000003"))
    with pytest.raises(ValueError, match=f"detections for 1 done sample folders of .* outside the selection \\(samples "
                                         f"\\[3\\]\\), first '{other}': give detections of the selection's samples only"):
        spadgen.evaluate(val, dict(picked, **{other: truth[other]}), out=tmp_path / "val2", program=spadgen_bin)
    m = spadgen.evaluate(ds, truth, out=tmp_path / "whole", program=spadgen_bin)  # the whole dataset: no selection
    assert "selection" not in m and len(m["samples"]) == 6
    with pytest.raises(ValueError, match="the selection holds no samples"):
        spadgen.evaluate(ds.select(where=lambda row: False), {}, program=spadgen_bin)
    # the temporary files in the folder asked for, removed afterwards
    (tmp_path / "scratch").mkdir()
    m = spadgen.evaluate(dataset_dir, truth, out=tmp_path / "mapping2", program=spadgen_bin, tmp_dir=tmp_path / "scratch")
    assert all(s["detections_source"]["file"].startswith(str(tmp_path / "scratch")) for s in m["samples"])
    assert list((tmp_path / "scratch").iterdir()) == []
    with pytest.raises(ValueError, match="first '000002'"):  # sample 2 failed
        spadgen.evaluate(dataset_dir, dict(truth, **{"000002": truth[sorted(truth)[0]]}), program=spadgen_bin)


def test_the_program_found_and_its_version(sweep_run, spadgen_bin, tmp_path, monkeypatch):
    from spadgen.evaluate import spadgen_program
    # a bare name is looked up on PATH, as a shell does (it was taken as ./spadgen)
    (tmp_path / "bin").mkdir()
    os.symlink(spadgen_bin, tmp_path / "bin" / "spadgen")
    monkeypatch.setenv("PATH", str(tmp_path / "bin") + os.pathsep + os.environ.get("PATH", ""))
    monkeypatch.setenv("SPADGEN_BIN", "spadgen")
    assert spadgen_program() == str(tmp_path / "bin" / "spadgen")
    # a program of another version is used, with a warning
    other = tmp_path / "other"
    other.write_text("#!/bin/sh\necho 9.9.9\n")
    other.chmod(0o755)
    with pytest.warns(UserWarning, match="says its version is '9.9.9', the package is"):
        assert spadgen_program(other) == str(other)
    # the temporary folder may not hold the placeholder; a target named like an option is a target
    weird = tmp_path / "t{sample}"
    weird.mkdir()
    run = spadgen.open_run(sweep_run)
    with pytest.raises(ValueError, match="holds {sample}"):
        spadgen.evaluate(run.path, np.full((run.height, run.width, 1), np.nan, np.float32), tmp_dir=weird, program=spadgen_bin)
    os.symlink(sweep_run, tmp_path / "-r")
    monkeypatch.chdir(tmp_path)
    m = spadgen.evaluate("-r", out=tmp_path / "dash", program=spadgen_bin)
    assert m["run"] == "-r"
    with pytest.raises(TypeError):
        spadgen.evaluate(run.path, region=(0.9, 0, 4, 4), program=spadgen_bin)
