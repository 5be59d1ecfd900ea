"""PyTorch Datasets over run folders and over a dataset folder (imported only when PyTorch is present:
``import spadgen`` never imports torch).

    from spadgen.torchdata import DatasetSamples, RunDataset
    ds = RunDataset(["out/a", "out/b"], patch_size=(64, 64))
    ds = DatasetSamples("out/plates", patch_size=(64, 64))      # every realisation of every done sample
    loader = torch.utils.data.DataLoader(ds, batch_size=8, shuffle=True)

Both load their samples the same way. One sample is a whole run's image, or with ``patch_size=(h, w)`` one
patch of a run: the images are cut into h x w patches from the top-left corner, ``patch_stride=(sy, sx)`` apart
(default: the patch size, non-overlapping; 1: every offset, for random crops drawn by a sampler), and a
remainder narrower than a patch at the right or bottom edge is left out. A sample is a dict of tensors; with
H, W the image's (or patch's) size, K the gate positions (or exposures), N the frames per k, L = ``max_layers``,
J = ``max_objects`` (default: the most of any run's ``ground_truth_objects``):

| key | shape | dtype | what |
|---|---|---|---|
| counts | (K, H, W) | float32 | sampled counts (integers, exact in float32) |
| expected_counts | (K, H, W) | float32 | noise-free expected counts N (1 - exp(-lambda)) (from detection_rate.npy when the run did not write expected_counts.npy) |
| detection_rate | (K, H, W) | float32 | noise-free lambda, mean avalanches per binary frame (never saturates) |
| depth | (1, H, W) | float32 | ground-truth range (m) of the nearest surface, 0 where there is none |
| depth_z | (1, H, W) | float32 | the same surface's z depth (m), along the optical axis (a depth map's), 0 where there is none |
| mask | (1, H, W) | bool | the pixel's ray hits a surface |
| layer_count | (H, W) | int64 | surfaces along the pixel's ray |
| layer_depth | (L, H, W) | float32 | range (m) of every surface along the ray, nearest first, 0 beyond layer_count |
| layer_mask | (L, H, W) | bool | layer l exists at the pixel (l < layer_count) |
| object_count | (H, W) | int64 | distinct objects along the pixel's ray (a plate over a sphere: 2 objects, 3 layers) |
| object_range | (J, H, W) | float32 | range (m) of each object's first surface along the ray, nearest first, 0 beyond object_count: what `spadgen evaluate` scores detections against |
| object_mask | (J, H, W) | bool | object slot j exists at the pixel (j < object_count) |
| object_id | (J, H, W) | int64 | the object slot j holds: its id in its run (Run.objects names it; runs of different scenes number their objects each their own way), -1 beyond object_count |
| object_detectable | (J, H, W) | bool | gate sweeps: slot j's object is detectable (labels.exr: its edge in the noise-free counts stands out; evaluate's "detectable") |
| object_path | (J, H, W) | float32 | the optical path (m) of slot j's direct return, laser to object to camera centre (its time of flight times c; 2 x range without a laser offset or a medium), 0 beyond object_count |
| object_edge_snr | (J, H, W) | float32 | gate sweeps: the signal-to-noise ratio of slot j's edge in the noise-free counts (labels.exr; detectable where >= 5), 0 beyond object_count |
| frames | (K, N, H, W) | uint8 | binary frames, 0 / 1 (large: only when asked for) |
| expected_counts_se | (K, H, W) | float32 | the Monte Carlo standard error of expected_counts (the rendered light's noise, which the noise-free targets carry), first-order: Run.expected_counts_error_bound (a loss weight or mask) |
| pde | (1, H, W) | float32 | the pixel's photon detection efficiency at the laser's wavelength, fill factor included (sensor_maps.exr): the chip's fixed pattern and the pixel design |
| pde_ambient | (1, H, W) | float32 | the same over the ambient light's band |
| dcr_cps | (1, H, W) | float32 | the pixel's dark count rate (counts per second) at the run's temperature |
| ambient_photons_per_s | (1, H, W) | float32 | the ambient light arriving on the pixel, photons per second (ambient.exr): the noise-free flux, an HDR target |
| laser_photons_per_pulse | (1, H, W) | float32 | the laser's return on the pixel, photons per pulse (laser.exr; runs that trace the laser) |
| gate_positions_ns | (K,) | float32 | gate positions (gate-sweep runs only) |
| exposures_us | (K,) | float32 | exposure of each image (intensity runs only: one, or the short and the long) |
| frames_per_k | () | int64 | N, the binary frames each count sums (counts / N is the detection probability) |
| intrinsics | (3, 3) | float32 | the sample's pinhole intrinsics (OpenCV convention, shifted to the patch) |
| origin | (2,) | int64 | (x, y) of the sample's top-left pixel in its run's image |
| run | () | int64 | index of the sample's run in ``paths`` (RunDataset: in ``runs``) |
| sample | () | int64 | DatasetSamples only: the sample's dataset index |
| repeat | () | int64 | DatasetSamples only: the realisation of the temporal noise (0: the sample's own folder) |
| parameters | (P,) | float32 | DatasetSamples only: the sample's numeric parameters, in the order of ``parameter_names`` |

``fields`` chooses among the first twenty-three (default: counts, expected_counts, depth, mask, layer_count);
gate_positions_ns (gate sweeps only), exposures_us (intensity runs only), frames_per_k, intrinsics, origin and run
come always, and with DatasetSamples sample,
repeat and parameters. Runs that share a DataLoader batch must agree on K (and N with frames); the constructor
checks that every run has what ``fields`` asks for.

A run folder replaced while the dataset is in use (a dataset run regenerating a stale sample, a new run into
the folder) raises spadgen.RunChangedError naming it, from the item that would read it: an item never mixes
two versions of a run. At most ``open_runs`` runs (default 64) are kept open per process (each holds a file
descriptor per memory-mapped stack and its decoded ground truth); the least recently used is closed first.
A run's counts are checked against frames_per_k once per run and process (Run.counts reads them once whole; a run
closed to stay within open_runs and opened again is not read again), not per item.
"""
from __future__ import annotations

import os
from collections import OrderedDict

import numpy as np

try:
    import torch
except ImportError as e:  # pragma: no cover - exercised only where torch is missing
    raise ImportError("spadgen.torchdata needs PyTorch (Debian 12: apt-get install python3-torch)") from e

from .dataset import Dataset, open_dataset
from .run import Run, RunChangedError, _position, open_run, unpack_frames

__all__ = ["RunDataset", "DatasetSamples", "FIELDS", "DEFAULT_FIELDS"]

FIELDS = ("counts", "expected_counts", "detection_rate", "depth", "depth_z", "mask", "layer_count", "layer_depth", "layer_mask",
          "object_count", "object_range", "object_mask", "object_detectable", "object_id", "object_path", "object_edge_snr", "frames",
          "expected_counts_se", "pde", "pde_ambient", "dcr_cps", "ambient_photons_per_s", "laser_photons_per_pulse")
DEFAULT_FIELDS = ("counts", "expected_counts", "depth", "mask", "layer_count")
# The file each field reads; a tuple: any one of them.
_NEEDS = {"counts": "counts.npy", "expected_counts": ("expected_counts.npy", "detection_rate.npy"),
          "detection_rate": "detection_rate.npy", "frames": "frames.npy",
          "depth": "ground_truth.exr", "depth_z": "ground_truth.exr", "mask": "ground_truth.exr", "layer_count": "ground_truth.exr",
          "layer_depth": "ground_truth.exr", "layer_mask": "ground_truth.exr", "object_count": "ground_truth.exr",
          "object_range": "ground_truth.exr", "object_mask": "ground_truth.exr", "object_detectable": "labels.exr",
          "object_id": "ground_truth.exr", "object_path": "ground_truth.exr", "object_edge_snr": "labels.exr", "expected_counts_se": "detection_rate.npy", "pde": "sensor_maps.exr",
          "pde_ambient": "sensor_maps.exr", "dcr_cps": "sensor_maps.exr", "ambient_photons_per_s": "ambient.exr",
          "laser_photons_per_pulse": "laser.exr"}


def _needs(field):
    """The files any one of which gives the field."""
    return _NEEDS[field] if isinstance(_NEEDS[field], tuple) else (_NEEDS[field],)


def _missing_field_message(run, field, need):
    """Why a run lacks a field, and what gives it: the keys that write the stacks (named without their
    container: a Zarr run's are .zarr stores), `spadgen sense` where the run saved its light and the field
    is a noise-free rate, or leaving the field out."""
    stems = [n[:-4] if n.endswith(".npy") else n for n in need]
    keys = [Run._WRITTEN_BY[n] for n in need if n in Run._WRITTEN_BY]
    msg = (f"{run.path}: field '{field}' needs {' or '.join(stems)}, which this run did not write"
           + (f" (written with {' or '.join(dict.fromkeys(keys))})" if keys else ""))
    rates = {"expected_counts", "detection_rate"}
    if field in rates and any(f.startswith("light/") for f in run.files):
        flag = "detection_rate" if field == "detection_rate" else "expected_counts"
        msg += (f"; it saved the light, from which `spadgen sense {run.path} --set outputs.{flag}=true -o DIR` writes "
                "it without rendering, bit for bit as a run would")
    # the default fields this run has (those needing the same missing file would fail next)
    fields = tuple(f for f in DEFAULT_FIELDS if f != field and any(run.has(n) for n in _needs(f)))
    return msg + f"; or leave '{field}' out of fields (e.g. fields={fields})"


class _RunSamples(torch.utils.data.Dataset):
    """What RunDataset and DatasetSamples share: run folders cut into samples (whole images or patches),
    checked once, and a sample loaded as a dict of tensors (the keys of the module's table but "run")."""

    def __init__(self, runs, patch_size=None, fields=DEFAULT_FIELDS, max_layers=None, open_runs=64, max_objects=None,
                 patch_stride=None):
        # one folder is one run (a path was iterated as its characters: "o: no such folder")
        runs = [runs] if isinstance(runs, (str, bytes, os.PathLike, Run)) else list(runs)
        self.paths = [r.path if isinstance(r, Run) else os.fspath(r) for r in runs]
        if not self.paths:
            raise ValueError(f"{type(self).__name__} needs at least one run folder")
        if isinstance(fields, str):
            raise ValueError(f"fields must be a list of field names, got the string {fields!r} (e.g. fields=[{fields!r}])")
        unknown = [f for f in fields if f not in FIELDS]
        if unknown:
            raise ValueError(f"unknown field(s) {unknown}; known: {', '.join(FIELDS)}")
        self.fields = tuple(fields)
        if int(open_runs) < 1:
            raise ValueError(f"open_runs must be at least 1, got {open_runs}")
        self.open_runs = int(open_runs)
        # The runs as they were checked here: a worker that opens one later must find the same folder.
        runs_ = [r if isinstance(r, Run) else open_run(p) for r, p in zip(runs, self.paths)]
        self._identities = [r._identity for r in runs_]
        self._runs = OrderedDict()
        self._counts_checked = set()  # runs whose counts this process checked (a run closed and opened again is not re-read)
        for r in runs_:
            for f in self.fields:
                need = _needs(f)
                if not any(r.has(n) for n in need):
                    raise ValueError(_missing_field_message(r, f, need))
                # ... and there: a file the run lists and lost is a damaged run, refused here rather than at the
                # item that reads it (a user's deleted counts.zarr was taken, and failed mid-epoch)
                listed = [r._file(n) for n in need if r.has(n)]
                if not any(os.path.exists(os.path.join(r.path, name)) for name in listed):
                    raise ValueError(f"{os.path.join(r.path, listed[0])}: listed in {os.path.join(r.path, 'metadata.json')} "
                                     f"(files) but missing, and field '{f}' reads it: the run folder is damaged; restore the "
                                     "file or run the scene again (a dataset's sample: `spadgen dataset run` generates it again)")
        modes = {r.mode for r in runs_}
        if len(modes) > 1:
            first = {m: next(r.path for r in runs_ if r.mode == m) for m in sorted(modes)}
            raise ValueError(f"the runs have different acquisition modes ({', '.join(f'{m} in {p}' for m, p in first.items())}): "
                             "a gate sweep's K gate positions and a 2D run's K exposures cannot share a batch")
        ks = {r.K for r in runs_}
        if len(ks) > 1:
            first = {k: next(r.path for r in runs_ if r.K == k) for k in sorted(ks)}
            raise ValueError(f"the runs have different K ({', '.join(f'{k} in {p}' for k, p in first.items())}, ...): "
                             "their samples cannot share a batch; make one per K (of a dataset, DatasetSamples(ds.select(...)) "
                             "of the samples of one K, by the parameter that sets it: the scene, the sweep's start, stop "
                             "or step, the exposure)")
        if "frames" in self.fields and len({r.frames_per_k for r in runs_}) > 1:
            first = {n: next(r.path for r in runs_ if r.frames_per_k == n) for n in sorted({r.frames_per_k for r in runs_})}
            raise ValueError(f"the runs have different frames per k ({', '.join(f'{n} in {p}' for n, p in first.items())}, "
                             "...): their frames cannot share a batch")
        def whole(value, what, least):
            # an integer (a float such as 7.9 was cut to 7 without a word), at least `least`
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < least:
                raise ValueError(f"{what} must be an integer >= {least}, got {value!r}")
            return int(value)

        self.max_layers = (whole(max_layers, "max_layers", 0) if max_layers is not None else
                           max(int(r.metadata["ground_truth_layers"]) for r in runs_))
        self.max_objects = (whole(max_objects, "max_objects", 0) if max_objects is not None else
                            max(int(r.metadata.get("ground_truth_objects", 0)) for r in runs_))
        if patch_size is None:
            if patch_stride is not None:
                raise ValueError(f"patch_stride {patch_stride!r} without patch_size: give the patches' size too")
            sizes = {(r.height, r.width) for r in runs_}
            if len(sizes) > 1:
                raise ValueError(f"the runs have different image sizes {sorted(sizes)}: give patch_size")
            self.index = [(i, 0, 0, r.height, r.width) for i, r in enumerate(runs_)]
        else:
            def pair(value, what, names):
                # one integer for both, or a pair of them, each >= 1
                sides = [value, value] if np.isscalar(value) else list(value)
                if len(sides) != 2:
                    raise ValueError(f"{what} must be an integer or a pair {names} of integers, got {value!r}")
                return tuple(whole(v, what, 1) for v in sides)

            ph, pw = pair(patch_size, "patch_size", "(h, w)")
            sy, sx = pair(patch_stride, "patch_stride", "(y, x)") if patch_stride is not None else (ph, pw)
            self.index = [(i, x, y, ph, pw) for i, r in enumerate(runs_)
                          for y in range(0, r.height - ph + 1, sy) for x in range(0, r.width - pw + 1, sx)]
            if not self.index:
                raise ValueError(f"no run is as large as a {ph} x {pw} patch")
        self.patch_size = patch_size
        self.patch_stride = patch_stride

    def _run(self, i):
        """Run i, opened in this process (each DataLoader worker opens its own: the cache is not pickled), the
        folder checked here; at most open_runs kept, the least recently used closed first."""
        if i in self._runs:
            self._runs.move_to_end(i)
            return self._runs[i]
        run = open_run(self.paths[i])
        if run._identity != self._identities[i]:
            raise RunChangedError(f"{self.paths[i]}: the run folder was replaced since {type(self).__name__} was made (a "
                                  "dataset run regenerated its sample, or a new run was published into it): make the "
                                  "dataset object again to read the new version")
        if i in self._counts_checked:  # the same folder (its identity, above) checked before it was closed
            run._cache["counts checked"] = True
        self._runs[i] = run
        while len(self._runs) > self.open_runs:
            self._runs.popitem(last=False)
        return run

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_runs"] = OrderedDict()  # the cache's type: _run moves and evicts in its order
        return state

    def __len__(self):
        return len(self.index)

    def _load(self, j):
        """(index of the sample's run in paths, the sample's tensors): read between two checks that the folder is
        the one checked when this object was made, so that its arrays come from one version."""
        given, j = j, _position(j)
        if j is None:
            raise TypeError(f"{type(self).__name__}[{given!r}]; expected an item's position (an int)")
        if not -len(self.index) <= j < len(self.index):
            raise IndexError(f"{type(self).__name__}[{j}] is past its {len(self.index)} items (0 to {len(self.index) - 1})")
        i, x, y, h, w = self.index[j]
        run = self._run(i)
        run.check_unchanged()
        out = self._read(run, x, y, h, w)
        run.check_unchanged()
        if "counts checked" in run._cache:
            self._counts_checked.add(i)
        return i, out

    def _read(self, run, x, y, h, w):
        ys, xs = slice(y, y + h), slice(x, x + w)
        out = {}
        if "counts" in self.fields:
            out["counts"] = torch.from_numpy(np.asarray(run.counts[:, ys, xs], np.float32))
        if "expected_counts" in self.fields:
            if run.has("expected_counts.npy"):
                e = np.array(run.expected_counts[:, ys, xs], np.float32)
            else:  # only the sample's part of lambda, not the whole run's expectation
                lam = np.asarray(run.detection_rate[:, ys, xs], np.float64)
                e = (run.frames_per_k * -np.expm1(-lam)).astype(np.float32)
            out["expected_counts"] = torch.from_numpy(e)
        if "detection_rate" in self.fields:
            out["detection_rate"] = torch.from_numpy(np.array(run.detection_rate[:, ys, xs], np.float32))
        if {"depth", "mask"} & set(self.fields):
            d = np.asarray(run.depth()[ys, xs], np.float32)
            hit = np.isfinite(d)
            if "depth" in self.fields:
                out["depth"] = torch.from_numpy(np.where(hit, d, 0).astype(np.float32)[None])
            if "mask" in self.fields:
                out["mask"] = torch.from_numpy(hit[None].copy())
        if "depth_z" in self.fields:
            z = np.asarray(run.depth("z")[ys, xs], np.float32)
            out["depth_z"] = torch.from_numpy(np.where(np.isfinite(z), z, 0).astype(np.float32)[None])
        if {"layer_count", "layer_depth", "layer_mask"} & set(self.fields):
            layers = run.layers()
            count = layers.count[ys, xs].astype(np.int64)
            if "layer_count" in self.fields:
                out["layer_count"] = torch.from_numpy(count)
            L = self.max_layers
            exists = np.arange(L)[:, None, None] < count[None]
            if "layer_depth" in self.fields:
                depth = np.zeros((L, h, w), np.float32)
                n = min(L, layers.range.shape[0])
                depth[:n] = layers.range[:n, ys, xs]
                out["layer_depth"] = torch.from_numpy(np.where(exists, depth, 0).astype(np.float32))
            if "layer_mask" in self.fields:
                out["layer_mask"] = torch.from_numpy(exists)
        if {"object_count", "object_range", "object_mask", "object_detectable", "object_id", "object_path", "object_edge_snr"} & set(self.fields):
            gt = run.ground_truth
            count = np.asarray(gt["object_count"][ys, xs]).astype(np.int64)
            J, n = self.max_objects, min(self.max_objects, int(run.metadata.get("ground_truth_objects", 0)))
            exists = np.arange(J)[:, None, None] < count[None]
            if "object_count" in self.fields:
                out["object_count"] = torch.from_numpy(count)

            def slots(source, name, dtype, unused):
                """Each slot's value of object<j>.<name> in source, `unused` beyond object_count."""
                a = np.full((J, h, w), unused, dtype)
                for j in range(n):
                    a[j] = source[f"object{j}.{name}"][ys, xs]
                return torch.from_numpy(np.where(exists, a, unused).astype(dtype))

            if "object_range" in self.fields:
                out["object_range"] = slots(gt, "range", np.float32, 0)
            if "object_mask" in self.fields:
                out["object_mask"] = torch.from_numpy(exists)
            if "object_id" in self.fields:  # which object each slot holds (slot 0 is the plate here, the sphere there)
                out["object_id"] = slots(gt, "id", np.int64, -1)
            if "object_detectable" in self.fields:
                out["object_detectable"] = slots(run.object_labels, "detectable", np.float32, 0) > 0.5
            if "object_path" in self.fields:
                out["object_path"] = slots(gt, "path", np.float32, 0)
            if "object_edge_snr" in self.fields:
                out["object_edge_snr"] = slots(run.object_labels, "edge_snr", np.float32, 0)
        if "expected_counts_se" in self.fields:
            out["expected_counts_se"] = torch.from_numpy(run.expected_counts_error_bound(ys, xs))
        for name in ("pde", "pde_ambient", "dcr_cps"):
            if name in self.fields:
                out[name] = torch.from_numpy(np.array(run.sensor_maps[name][ys, xs], np.float32)[None])
        if "ambient_photons_per_s" in self.fields:
            out["ambient_photons_per_s"] = torch.from_numpy(np.array(run.ambient["photons_per_second"][ys, xs], np.float32)[None])
        if "laser_photons_per_pulse" in self.fields:
            out["laser_photons_per_pulse"] = torch.from_numpy(np.array(run.laser["photons_per_pulse"][ys, xs], np.float32)[None])
        if "frames" in self.fields:
            packed = run.frames_packed[:, :, ys]
            out["frames"] = torch.from_numpy(np.ascontiguousarray(unpack_frames(packed, run.width)[..., xs]))
        if run.mode == "gate_sweep":
            out["gate_positions_ns"] = torch.from_numpy(run.gate_positions_ns.astype(np.float32))
        else:
            out["exposures_us"] = torch.from_numpy((run.exposures_s * 1e6).astype(np.float32))
        out["frames_per_k"] = torch.tensor(run.frames_per_k, dtype=torch.int64)
        K = run.intrinsics.copy()
        K[0, 2] -= x
        K[1, 2] -= y
        out["intrinsics"] = torch.from_numpy(K.astype(np.float32))
        out["origin"] = torch.tensor([x, y], dtype=torch.int64)
        return out


class RunDataset(_RunSamples):
    """Samples (whole images or patches) of a list of run folders (paths or spadgen.Run objects; one of them alone
    is taken as a list of one); see the module's table for each key."""

    def __getitem__(self, j):
        i, out = self._load(j)
        out["run"] = torch.tensor(i, dtype=torch.int64)
        return out



class DatasetSamples(_RunSamples):
    """Samples of a dataset folder (``spadgen dataset run``): every realisation of every selected sample, whole or
    cut into patches, in dataset index order, then realisation, then patch (row-major). Each item has RunDataset's
    keys and:

    | key | shape | dtype | what |
    |---|---|---|---|
    | sample | () | int64 | the sample's dataset index |
    | repeat | () | int64 | the realisation of the temporal noise (0: the sample's folder, r: samples/<i>_rNN) |
    | parameters | (P,) | float32 | the sample's numeric parameters, in the order of ``parameter_names`` |

    ("run" indexes ``paths``, one per realisation.) ``parameter_names`` are the dataset's parameters that are
    numbers or booleans (as 0 / 1) in every sample of the dataset, in index.csv's column order (the grid keys, then
    the random keys, as the dataset file lists them); string and array parameters (the scene, a sensor preset, a
    crop) are not among them: ``dataset.index`` has every parameter of every sample.

    dataset     a spadgen.Dataset (or a selection of one: ds.select(...)) or a dataset folder's path;
    repeats     "all": every realisation; "first": realisation 0 only; "pairs": every realisation r, each item
                with the counts of another realisation of the same sample and patch, for Noise2Noise training
                (the same light and chip, independent temporal noise):

                | key | shape | dtype | what |
                |---|---|---|---|
                | counts_pair | (K, H, W) | float32 | the counts of realisation (r + 1) mod R of the sample (R: its realisations) |
                | repeat_pair | () | int64 | that realisation |

                (every sample taken must have two realisations or more: the dataset's repeats >= 2);
    status      the samples to take ("done", or several in a list; None: all): every one taken must be done,
                so the default leaves out failed, stale and missing samples, and status=None refuses a dataset
                that has any.
    """

    def __init__(self, dataset, fields=DEFAULT_FIELDS, patch_size=None, repeats="all", status="done", max_layers=None,
                 open_runs=64, max_objects=None, patch_stride=None):
        ds = dataset if isinstance(dataset, Dataset) else open_dataset(dataset)
        if repeats not in ("all", "first", "pairs"):
            raise ValueError(f"repeats must be 'all', 'first' or 'pairs', got {repeats!r}")
        view = ds.select(status=status) if status is not None else ds
        not_done = [r["index"] for r in view.index if r["status"] != "done"]
        if not_done:
            raise ValueError(f"{ds.path}: samples {not_done} are not done (their status: "
                             f"{sorted({r['status'] for r in view.index if r['status'] != 'done'})}): only done samples "
                             "have runs; status='done' leaves the others out")
        if not len(view):
            counts = ", ".join(f"{n} {s}" for s, n in ds.status_counts().items() if n)
            raise ValueError(f"{ds.path}: no sample to load with status={status!r} "
                             + (f"(the {len(ds)} samples: {counts})" if len(ds) else "(the selection is empty)"))
        self.dataset = view
        self.repeats = repeats
        self.parameter_names = tuple(ds.numeric_parameter_keys)
        runs, self.realisations = [], []
        params = []
        self._pair = []  # repeats="pairs": the run index of each run's partner (the next realisation of its sample)
        for s in view:
            vector = [float(s.parameters[k]) for k in self.parameter_names]
            taken = s.realisations if repeats != "first" else [s.run]
            if repeats == "pairs" and len(taken) < 2:
                raise ValueError(f"{ds.path}: sample {s.index} has {len(taken)} realisation(s) of the temporal noise: "
                                 "repeats='pairs' pairs two realisations of each sample (the dataset file's repeats >= 2; "
                                 "repeats may grow in a dataset folder: `spadgen dataset run` with a larger repeats adds "
                                 "them, from each sample's saved light, which a dataset of repeats 1 does not keep unless it "
                                 "sets outputs.light: its samples are rendered again)")
            first = len(runs)
            for r, run in enumerate(taken):
                runs.append(run)
                self.realisations.append((s.index, r))
                params.append(vector)
                self._pair.append(first + (r + 1) % len(taken))
        self._parameters = np.array(params, np.float32).reshape(len(runs), len(self.parameter_names))
        super().__init__(runs, patch_size=patch_size, fields=fields, max_layers=max_layers, open_runs=open_runs,
                         max_objects=max_objects, patch_stride=patch_stride)

    def __getitem__(self, j):
        i, out = self._load(j)
        sample, repeat = self.realisations[i]
        out["run"] = torch.tensor(i, dtype=torch.int64)
        out["sample"] = torch.tensor(sample, dtype=torch.int64)
        out["repeat"] = torch.tensor(repeat, dtype=torch.int64)
        out["parameters"] = torch.from_numpy(self._parameters[i].copy())
        if self.repeats == "pairs":
            _, x, y, h, w = self.index[j]
            other = self._run(self._pair[i])
            other.check_unchanged()
            counts = np.asarray(other.counts[:, y:y + h, x:x + w], np.float32)
            other.check_unchanged()
            out["counts_pair"] = torch.from_numpy(counts)
            out["repeat_pair"] = torch.tensor(self.realisations[self._pair[i]][1], dtype=torch.int64)
        return out
