"""docs/python.md's worked example and its Datasets section, run as written, in order: each section's Python
blocks in one namespace, its shell blocks through bash, in a folder where `scenes/` and `python/` are the
repository's and `build/app/spadgen` is the built program; for the worked example `out/multi_object` is a
small run of the same scene (and the training runs are told to use fewer gate positions and samples, so that
they take a second). The Datasets section's dataset is small as written and is generated as written."""
import os
import re
import subprocess
import sys

import pytest

from conftest import SOURCE

pytest.importorskip("torch")
pytest.importorskip("matplotlib")

FAST = "--set acquisition.gate_sweep.step_ps=360 --set render.samples_per_pixel=1"


def section_blocks(title):
    text = (SOURCE / "docs" / "python.md").read_text()
    section = text.split(f"\n## {title}\n", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"```(python|sh)\n(.*?)```", section, re.S)


def run_blocks(blocks, folder, spadgen_bin, monkeypatch, sets=""):
    """Runs the blocks in `folder` (with scenes/ and python/ linked in); returns the Python namespace."""
    for name in ("scenes", "python"):
        os.symlink(SOURCE / name, folder / name)
    monkeypatch.chdir(folder)
    namespace = {}
    for kind, code in blocks:
        if kind == "python":
            exec(compile(code, "docs/python.md", "exec"), namespace)
        else:
            script = code.replace("build/app/spadgen", spadgen_bin).replace(" -o out/train", f" {sets} -o out/train")
            script = script.replace("python3 -m", f"{sys.executable} -m")
            subprocess.run(["bash", "-euo", "pipefail", "-c", script], check=True)
    return namespace


def test_worked_example_runs(sweep_run, spadgen_bin, tmp_path, monkeypatch):
    blocks = section_blocks("Worked example")
    assert [kind for kind, _ in blocks].count("python") >= 5 and any("RunDataset" in code for _, code in blocks)
    (tmp_path / "out").mkdir()
    os.symlink(sweep_run, tmp_path / "out" / "multi_object")
    namespace = run_blocks(blocks, tmp_path, spadgen_bin, monkeypatch, FAST)
    for f in ("out/depth.png", "out/profiles.png", "out/overview.png", "out/multi_object.xyz"):
        assert (tmp_path / f).stat().st_size > 0, f
    assert namespace["xyz"].shape[1] == 3 and len(namespace["ds"]) == 3 * (128 // 32) * (256 // 32)


def test_datasets_section_runs(spadgen_bin, tmp_path, monkeypatch):
    blocks = section_blocks("Datasets")
    assert [kind for kind, _ in blocks] == ["sh", "python", "python", "python", "python"]
    ns = run_blocks(blocks, tmp_path, spadgen_bin, monkeypatch)
    # What the comments of the section say.
    assert repr(ns["ds"]) == "Dataset('out/plates', 4 samples: 4 done)"
    assert ns["ds"].parameter_keys == ["scene", "laser.average_power_mW", "ambient.illuminance_lux"]
    assert ns["t"]["laser.average_power_mW"].tolist() == [1, 2, 1, 2]
    assert ns["t"]["ambient.illuminance_lux"].round(1).tolist() == [4.1, 97.6, 47.4, 558.6]
    assert ns["t"]["hit_fraction"].tolist() == [1.0] * 4
    assert ns["strong"].indices.tolist() == [1, 3] and ns["dim"].indices.tolist() == [0, 1, 2]
    assert ns["run"].counts.shape == (351, 64, 64)
    assert (len(ns["train"]), len(ns["val"])) == (24, 4)
    assert ns["train"].parameter_names == ("laser.average_power_mW", "ambient.illuminance_lux")
    assert ns["val_loss"] > 0 and (tmp_path / "out" / "plates" / "samples" / "000003_r01" / "counts.npy").is_file()
    assert len(ns["m"]["samples"]) == 8 and ns["m"]["objects"]["recall"] == 1.0
    assert round(ns["m"]["range_error"]["bias_mm"], 3) == 3.0 and (tmp_path / "out" / "plates_scores" / "metrics.json").is_file()
