"""Shared fixtures of the Python package's tests: the spadgen program and exr_tool (paths from CTest through
SPADGEN_BIN, SPADGEN_EXR_TOOL and SPADGEN_ZARR_TOOL, else the README's build folder), and small real runs of shipped scenes,
made once per test process."""
import json
import os
import pathlib
import subprocess

import pytest

SOURCE = pathlib.Path(os.environ.get("SPADGEN_SOURCE_DIR", pathlib.Path(__file__).resolve().parents[2]))
SCENES = SOURCE / "scenes" / "paper"

# Each run: scene file and --set overrides. Small crops of shipped scenes, well under a second each.
RUNS = {
    # The multi-object scene across the plate's edge (x < 512: plate in front of the sphere, 3 layers), the
    # bare sphere, and past the sphere's edge (x > 826: nothing hit); 347 pixels across, not a multiple of 8.
    # Every optional stack: transients (on a smaller crop), their indirect part, binary frames.
    "sweep": ("multi_object.json", ["camera.crop=[490,236,347,10]", "render.samples_per_pixel=2",
                                    "acquisition.gate_sweep.step_ps=360", "outputs.transient=true",
                                    "outputs.transient_crop=[500,238,24,6]", "render.split_direct_indirect=true",
                                    "outputs.frames=true", "outputs.expected_counts=true", "outputs.light=true"]),
    # The same as Zarr stores (outputs.storage = zarr): every stack, the saved light and the transients.
    "sweep_zarr": ("multi_object.json", ["camera.crop=[490,236,347,10]", "render.samples_per_pixel=2",
                                         "acquisition.gate_sweep.step_ps=360", "outputs.transient=true",
                                         "outputs.transient_crop=[500,238,24,6]", "render.split_direct_indirect=true",
                                         "outputs.frames=true", "outputs.expected_counts=true", "outputs.light=true",
                                         "outputs.storage=zarr"]),
    # Dual-exposure intensity images of the test chart (uint16 counts, intensity.exr), with frames.
    "intensity": ("test_chart_dual.json", ["camera.crop=[400,300,40,24]", "outputs.frames=true"]),
    # The camera moved, turned and rolled in front of the multi-object scene: the plate's front face
    # (world z = -0.45 m) and the pose must agree.
    "posed": ("multi_object.json", ["camera.position_m=[0.05,0.03,0.1]", "camera.look_at_m=[-0.05,0,-0.75]",
                                    "camera.up=[0.3,1,0]", "camera.crop=[540,160,64,48]", "render.samples_per_pixel=1",
                                    "acquisition.gate_sweep.step_ps=3600", "outputs.previews=false"]),
    # The multi-object scene at its default 16 paths: the plate alone (its light from inside it and its ghost
    # of the laser) and the bare sphere beside the plate's edge (the edge's grazing glint); test_fireflies.py.
    "plate_alone": ("multi_object.json", ["camera.crop=[0,0,256,128]", "acquisition.gate_sweep.step_ps=3600",
                                          "outputs.previews=false"]),
    "edge_glint": ("multi_object.json", ["camera.crop=[560,0,40,500]", "acquisition.gate_sweep.step_ps=3600",
                                         "outputs.previews=false"]),
    # The saved light and the counts, no noise-free rates (the shipped dataset example's storage).
    "light_only": ("flat_target.json", ["camera.crop=[507,245,10,10]", "render.samples_per_pixel=2", "outputs.light=true",
                                        "outputs.detection_rate=false", "outputs.previews=false"]),
    # The paper's flat target at 0.8 m, central pixels, every 36 ps gate step (as tests/app/paper_test.cpp).
    "flat": ("flat_target.json", ["camera.position_m=[0,0,0.8]", "camera.crop=[507,245,10,10]",
                                  "render.samples_per_pixel=4", "outputs.previews=false"]),
    # The same under 100 lux of ambient light: a floor of about half the plateau's counts.
    "flat_lit": ("flat_target.json", ["camera.position_m=[0,0,0.8]", "camera.crop=[507,245,10,10]",
                                      "render.samples_per_pixel=4", "outputs.previews=false", "ambient.illuminance_lux=100"]),
}


def _tool(env, default):
    path = pathlib.Path(os.environ.get(env, SOURCE / "build" / default))
    if not path.is_file():
        pytest.fail(f"{path} does not exist: build spadgen first, or set {env} (ctest sets it)")
    return str(path)


@pytest.fixture(scope="session")
def spadgen_bin():
    return _tool("SPADGEN_BIN", "app/spadgen")


@pytest.fixture(scope="session")
def exr_tool():
    return _tool("SPADGEN_EXR_TOOL", "tests/python/exr_tool")


@pytest.fixture(scope="session")
def zarr_tool():
    return _tool("SPADGEN_ZARR_TOOL", "tests/python/zarr_tool")


@pytest.fixture(scope="session")
def make_run(spadgen_bin, tmp_path_factory):
    """make_run(name) -> the folder of run RUNS[name], run on first use."""
    done = {}

    def make(name):
        if name not in done:
            scene, sets = RUNS[name]
            out = tmp_path_factory.mktemp(name)
            cmd = [spadgen_bin, "run", str(SCENES / scene), "-o", str(out), "-q"]
            for s in sets:
                cmd += ["--set", s]
            subprocess.run(cmd, check=True)
            done[name] = out
        return done[name]

    return make


@pytest.fixture(scope="session")
def sweep_run(make_run):
    return make_run("sweep")


@pytest.fixture(scope="session")
def intensity_run(make_run):
    return make_run("intensity")


# A small dataset (spadgen dataset run): 3 grid cells of camera.width_px x random keys, 4 samples, 2 realisations of
# the temporal noise. Sample 2 (width 16: the crop leaves the sensor) fails; samples 0 and 3 (width 1024) and 1
# (1000) are done. Scene paths are relative to the dataset file (as the docs write them).
DATASET = """{
  "description": "python test dataset", "seed": 3,
  "scenes": ["scenes/multi_object.json"],
  "samples": 4,
  "set": {"render.samples_per_pixel": 2, "acquisition.gate_sweep.stop_ns": 4.2, "camera.crop": [496, 232, 24, 20]},
  "grid": {"camera.width_px": [1024, 1000, 16]},
  "random": {"laser.average_power_mW": {"uniform": [1, 3]}, "ambient.illuminance_lux": {"log_uniform": [1, 1000]},
             "sensor.preset": {"choice": ["pixel_A", "pixel_B"]}},
  "seeds": {"chip": 1}, "repeats": 2
}
"""


@pytest.fixture(scope="session")
def dataset_dir(spadgen_bin, tmp_path_factory):
    """The folder of DATASET, generated once per test process (about 2 s)."""
    root = tmp_path_factory.mktemp("dataset")
    (root / "scenes").symlink_to(SCENES)
    (root / "d.json").write_text(DATASET)
    out = root / "out"
    r = subprocess.run([spadgen_bin, "dataset", "run", str(root / "d.json"), "-o", str(out), "-q"],
                       capture_output=True, text=True)
    # The failing sample makes the run exit 1 after generating the others.
    assert r.returncode == 1 and "1 sample failed (2)" in r.stderr, r.stderr
    return out


# Damage for the soak tests: values of another type or out of range, or a key or element removed, at a place of
# a JSON document drawn from rng (random.Random with a fixed seed).
DAMAGE = [None, True, "x", "", -1, 0, 1, 0.5, 1e308, -1e308, 1e-308, 2**63 - 1, 2**64 - 1, [], {}, [1, 2, 3], {"a": 1}, "\u00e9"]


def json_places(v, at=()):
    """Every place of a JSON document but its root (tuples of keys and indices), depth first."""
    out = [at] if at else []
    if isinstance(v, dict):
        for k, e in v.items():
            out += json_places(e, at + (k,))
    elif isinstance(v, list):
        for i, e in enumerate(v):
            out += json_places(e, at + (i,))
    return out


def damage_at(doc, at, value):
    """Sets doc's place `at` to value in place (... removes it); returns what it did ("a/b = 1e+308", "a/b removed")."""
    parent = doc
    for k in at[:-1]:
        parent = parent[k]
    where = "/".join(map(str, at))
    if value is ...:
        del parent[at[-1]]
        return where + " removed"
    parent[at[-1]] = value
    return where + " = " + json.dumps(value)


def damage_json(doc, rng):
    """Damages doc in place at one of its places drawn from rng; returns what it did, as damage_at."""
    at = rng.choice(json_places(doc))
    v = rng.randrange(len(DAMAGE) + 2)  # the last two: remove it
    return damage_at(doc, at, DAMAGE[v] if v < len(DAMAGE) else ...)
