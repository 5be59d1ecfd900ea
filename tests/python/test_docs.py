"""docs/python.md's worked example, run as written, in order: its Python blocks in one namespace, its shell
blocks through bash, in a folder where `out/multi_object` is a small run of the same scene, `scenes/` and
`python/` are the repository's and `build/app/spadgen` is the built program (told to use fewer gate positions
and samples, so the training runs take a second)."""
import os
import re
import subprocess
import sys

import pytest

from conftest import SOURCE

pytest.importorskip("torch")
pytest.importorskip("matplotlib")

FAST = "--set acquisition.gate_sweep.step_ps=360 --set render.samples_per_pixel=1"


def worked_example_blocks():
    text = (SOURCE / "docs" / "python.md").read_text()
    section = text.split("## Worked example", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"```(python|sh)\n(.*?)```", section, re.S)


def test_worked_example_runs(sweep_run, spadgen_bin, tmp_path, monkeypatch):
    blocks = worked_example_blocks()
    assert [kind for kind, _ in blocks].count("python") >= 5 and any("RunDataset" in code for _, code in blocks)
    (tmp_path / "out").mkdir()
    os.symlink(sweep_run, tmp_path / "out" / "multi_object")
    for name in ("scenes", "python"):
        os.symlink(SOURCE / name, tmp_path / name)
    monkeypatch.chdir(tmp_path)
    namespace = {}
    for kind, code in blocks:
        if kind == "python":
            exec(compile(code, "docs/python.md", "exec"), namespace)
        else:
            script = code.replace("build/app/spadgen", spadgen_bin).replace(" -o out/train", f" {FAST} -o out/train")
            script = script.replace("python3 -m", f"{sys.executable} -m")
            subprocess.run(["bash", "-euo", "pipefail", "-c", script], check=True)
    for f in ("out/depth.png", "out/profiles.png", "out/overview.png", "out/multi_object.xyz"):
        assert (tmp_path / f).stat().st_size > 0, f
    assert namespace["xyz"].shape[1] == 3 and len(namespace["ds"]) == 3 * (128 // 32) * (256 // 32)
