"""A dataset folder (what ``spadgen dataset run FILE -o DIR`` writes): its index as a table, filtering, and its
samples as runs.

    ds = spadgen.open_dataset("out/plates")
    ds.table()["hit_fraction"]                       # (S,) float64, one entry per sample
    done = ds.select(status="done", laser__average_power_mW=2)
    for sample in done:
        sample.index, sample.parameters, sample.run.counts, [r.counts for r in sample.repeats]

Opening reads dataset.json and index.jsonl only; a sample's run folder is opened when ``sample.run`` is first
used. Everything comes from the index as the last ``spadgen dataset run`` into the folder wrote it
(``spadgen dataset status DIR`` tells what is on disk now).
"""
from __future__ import annotations

import fcntl
import json
import math
import numbers
import os
import struct
import warnings

import numpy as np

from .run import _position, load_json, open_run

__all__ = ["Dataset", "Sample", "SampleNotDoneError", "open_dataset", "STATUSES", "SUMMARY_COLUMNS"]

STATUSES = ("done", "failed", "stale", "missing", "damaged")
# The ground-truth summary of a done sample (index.jsonl "ground_truth"), in index.csv's order.
SUMMARY_COLUMNS = ("hit_fraction", "range_min_m", "range_max_m", "meshes_in_view", "max_layer_count",
                   "objects_in_view", "max_object_count", "multi_object_fraction", "objects_detectable",
                   "detectable_fraction", "laser_photons_per_pulse")
_SEEDS = (("seed", "seed"), ("seed_light", "light"), ("seed_chip", "chip"), ("seed_noise", "noise"))


class SampleNotDoneError(RuntimeError):
    """A sample's run was asked for, but the sample is not done (failed, stale, missing or damaged), or its
    folder holds another generation of it than the index.jsonl this Dataset read."""


def _is_number(v):
    return isinstance(v, numbers.Real) and not isinstance(v, bool)


def _kind(values):
    """The column type of a parameter's values: "bool", "int", "float", "str" or "object"."""
    if values and all(isinstance(v, bool) for v in values):
        return "bool"
    if values and all(isinstance(v, numbers.Integral) and not isinstance(v, bool) for v in values):
        return "int"
    if values and all(_is_number(v) for v in values):
        return "float"
    if all(isinstance(v, str) for v in values):
        return "str"
    return "object"


def _same(a, b):
    """Parameter equality, a JSON array equal to a list or tuple of the same values."""
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, (list, tuple)) or isinstance(b, (list, tuple)):
        return False
    return a == b


def _check_index(rows, index_path):
    """The rows of index.jsonl as `spadgen dataset run` writes them (as `spadgen evaluate` checks them): an object
    per row with an integer "index", strings "status", "folder" (samples/NAME) and "sample_hash", objects
    "parameters" and "seeds", a list of folders "repeats"; no sample and no folder listed twice. Row N counts
    the non-blank lines from 1, as the program's messages do. A damaged row was a TypeError, AttributeError or
    KeyError from wherever it was read, and a row copied by hand read (and trained on) its sample twice."""
    damaged = "the index was damaged after `spadgen dataset run` wrote it: run the dataset again to write it"
    indices, folders = {}, {}
    for n, r in enumerate(rows, 1):
        where = f"{index_path} row {n}"
        if not isinstance(r, dict):
            raise ValueError(f"{where}: not a JSON object (an index row spadgen writes is one); {damaged}")
        i = r.get("index")
        if isinstance(i, bool) or not isinstance(i, int) or not 0 <= i < 1 << 62:
            raise ValueError(f"{where}: expected an integer \"index\" >= 0, found {json.dumps(i)[:40]}; {damaged}")
        for key in ("status", "folder", "sample_hash"):
            if key in r or key != "sample_hash":
                if not isinstance(r.get(key), str):
                    raise ValueError(f"{where}: expected a string \"{key}\", found {json.dumps(r.get(key))[:40]}; {damaged}")
        if r["status"] not in STATUSES:
            raise ValueError(f"{where}: status {json.dumps(r['status'])[:40]} is not one of {', '.join(STATUSES)}; {damaged}")
        for key in ("parameters", "seeds"):
            if not isinstance(r.get(key), dict):
                raise ValueError(f"{where}: expected an object \"{key}\", found {json.dumps(r.get(key))[:40]}; {damaged}")
        repeats = r.get("repeats", [])
        if not isinstance(repeats, list) or not all(isinstance(f, str) for f in repeats):
            raise ValueError(f"{where}: expected a list of folders \"repeats\", found {json.dumps(repeats)[:40]}; {damaged}")
        for key, kind in (("ground_truth", dict), ("warnings", list), ("error", str)):
            if r.get(key) is not None and not isinstance(r[key], kind):
                raise ValueError(f"{where}: \"{key}\" is {json.dumps(r[key])[:40]}, not a{'n object' if kind is dict else ' list' if kind is list else ' string'}; {damaged}")
        # what table() makes columns of (a seed removed was a KeyError, one of another type a TypeError or an
        # OverflowError, a warnings of null a TypeError: a soak's finds)
        for _, key in _SEEDS:
            v = r["seeds"].get(key)
            if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v < 1 << 63:
                raise ValueError(f"{where}: seeds.{key} is {json.dumps(v)[:40]}, not an integer in [0, 2^63); {damaged}")
        if "warnings" in r and not (isinstance(r["warnings"], list) and all(isinstance(w, str) for w in r["warnings"])):
            raise ValueError(f"{where}: \"warnings\" is {json.dumps(r['warnings'])[:40]}, not a list of texts; {damaged}")
        for key, v in [("bytes", r.get("bytes", 0))] + [(f"ground_truth.{k}", v) for k, v in (r.get("ground_truth") or {}).items()]:
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float))):
                raise ValueError(f"{where}: {key} is {json.dumps(v)[:40]}, not a number; {damaged}")
        if i in indices:
            raise ValueError(f"{where}: lists sample {i} again (row {indices[i]} lists it); {damaged}")
        indices[i] = n
        for f in [r["folder"]] + repeats:
            parts = f.replace("\\", "/").split("/")
            if os.path.isabs(f) or len(parts) < 2 or parts[0] != "samples" or any(p in ("", ".", "..") for p in parts[1:]):
                raise ValueError(f"{where}: lists the folder {f}, not a sample folder of the dataset (samples/NAME); {damaged}")
            key = os.path.normpath(f)
            if key in folders:
                raise ValueError(f"{where}: lists the folder {f} again (row {folders[key]} lists it); {damaged}")
            folders[key] = n


def _spec_samples(spec):
    """The number of samples dataset.json asks for: "samples", or one per grid cell (the scene files times each
    grid key's values) when it is null; None when the file does not say (not as spadgen writes it)."""
    n = spec.get("samples")
    if isinstance(n, int) and not isinstance(n, bool):
        return n
    scenes, grid = spec.get("scenes"), spec.get("grid", {})
    if n is not None or not isinstance(scenes, list) or not isinstance(grid, dict) or \
            not all(isinstance(v, list) for v in grid.values()):
        return None
    return math.prod([len(scenes)] + [len(v) for v in grid.values()])


def _runs_on(path):
    """Whether a `spadgen dataset run` is on the dataset folder now: it holds a shared lock on byte 0 of
    .dataset.runs for as long as it runs (datasets/folder.cpp, dataset_runs_on)."""
    try:
        fd = os.open(os.path.join(path, ".dataset.runs"), os.O_RDONLY | os.O_CLOEXEC)
    except OSError:
        return False  # no run ever entered
    try:
        # struct flock: l_type, l_whence (short), l_start, l_len (off_t), l_pid (int)
        query = struct.pack("hhqqi4x", fcntl.F_WRLCK, os.SEEK_SET, 0, 1, 0)
        return struct.unpack("hhqqi4x", fcntl.fcntl(fd, fcntl.F_OFD_GETLK, query))[0] != fcntl.F_UNLCK
    except OSError:
        return False
    finally:
        os.close(fd)


def _check_rows_against_spec(rows, spec, path, index_path):
    """index.jsonl holds one row per sample of dataset.json, in index order, as `spadgen dataset run` writes it
    (and `spadgen dataset status` checks it): an index cut short on a line boundary, or a row removed, was read as
    a smaller dataset without a word. While a run is on the folder, dataset.json is that run's (written as it
    begins) and the index the last finished run's: a difference in number is then said, not refused."""
    fix = "`spadgen dataset status` names what is wrong; `spadgen dataset run` writes the index again"
    for n, r in enumerate(rows):
        if r["index"] != n:
            raise ValueError(f"{index_path} row {n + 1}: lists sample {r['index']} where sample {n} belongs (index.jsonl "
                             f"lists every sample in index order): the index was damaged after it was written; {fix}")
    want = _spec_samples(spec)
    if want is None or want == len(rows):
        return
    said = (f"{index_path} has {len(rows)} rows for the {want} samples of {os.path.join(path, 'dataset.json')}")
    if _runs_on(path):
        warnings.warn(f"{said}: a `spadgen dataset run` is on the folder now, and the last run to end writes the "
                      "index; this Dataset holds the rows written so far", stacklevel=4)
        return
    if len(rows) < want:
        # (the usual cause: a run that raised "samples" writes dataset.json as it begins and the index as it ends)
        raise ValueError(f"{said}: a `spadgen dataset run` that changed the dataset's samples was killed before it "
                         "wrote the index, or the index was cut short after it was written; `spadgen dataset run` with "
                         "the dataset file generates what is left and writes the index again (run with the dataset file "
                         "the folder held before, it writes only the index and the card)")
    raise ValueError(f"{said}: the index was added to, or dataset.json edited, after they were written; {fix}")


class Sample:
    """One sample of a dataset: its row of the index, and its run folders opened on first use."""

    def __init__(self, dataset, row):
        self._dataset_path = dataset.path
        self.row = row
        self.index = int(row["index"])
        self.status = row["status"]
        self.folder = os.path.abspath(os.path.join(dataset.path, row["folder"]))
        self.parameters = dict(row["parameters"])
        self.seeds = dict(row["seeds"])
        self.sample_hash = row.get("sample_hash", "")
        self.ground_truth = dict(row.get("ground_truth") or {})
        self.error = row.get("error")
        # What the sample's run warned about (metadata.json's warnings): settings that are consistent but likely
        # not what was meant (a frame longer than the camera's); [] where the sample is not done.
        self.warnings = list(row.get("warnings") or [])
        # Realisations 1, 2, ... of the temporal noise (realisation 0 is the sample's own folder).
        self.repeat_folders = [os.path.abspath(os.path.join(dataset.path, f)) for f in row.get("repeats", [])]
        self._runs = {}

    def __repr__(self):
        return f"Sample({self.index}, {self.status}, {self.parameters})"

    def _open(self, r):
        if self.status != "done":
            where = f"{self._dataset_path}: sample {self.index} ({os.path.relpath(self.folder, self._dataset_path)})"
            raise SampleNotDoneError(where + {
                "failed": f" failed, so it has no run: {(self.error or '').strip()}",
                "stale": " is stale: its folder holds an earlier version of it (the scene file, a glTF file or spadgen "
                         "changed since); `spadgen dataset run` generates it again, spadgen.open_run(folder) reads the old one",
                "missing": " is missing: it has not been generated yet (`spadgen dataset run` generates it)",
                "damaged": f" is damaged: {(self.error or '').strip()} (`spadgen dataset run` generates it again, "
                           "unless its folder holds files its metadata.json does not list: `spadgen dataset status` "
                           "says which)",
            }.get(self.status, f" is {self.status}, not done"))
        if r not in self._runs:
            folder = self.folder if r == 0 else self.repeat_folders[r - 1]
            if not os.path.lexists(folder):  # (open_run said "no such folder", without the index or the remedy)
                raise SampleNotDoneError(
                    f"{folder}: {os.path.join(self._dataset_path, 'index.jsonl')} lists realisation {r} of sample "
                    f"{self.index} done (hash {self.sample_hash}), and its folder does not exist: the sample was removed "
                    "or changed since the index was written; `spadgen dataset run` brings the index up to date (and "
                    "generates what is not done), then open the dataset again (spadgen.open_dataset)")
            run = open_run(folder)
            section = run.metadata.get("dataset", {})
            found = (section.get("index"), section.get("repeat"), section.get("sample_hash"))
            if found != (self.index, r, self.sample_hash):
                raise SampleNotDoneError(
                    f"{folder}: its metadata.json's dataset section (sample, realisation, hash {found}) is not realisation {r} "
                    f"of sample {self.index} as this Dataset read index.jsonl (hash {self.sample_hash!r}): the sample "
                    "was generated again since; open the dataset again (spadgen.open_dataset) to read the new index, "
                    "or, if index.jsonl itself is behind (a `spadgen dataset run` into the folder was stopped), run it again")
            # The row's parameters and seeds are the folder's (`spadgen dataset status` compares them too): an
            # index edited to other parameters made select() return samples by values they were not made with.
            seeds = dict(self.seeds)
            if isinstance(seeds.get("noise"), int):
                seeds["noise"] += r
            for what, listed, own in (("parameters", self.parameters, section.get("parameters")),
                                      ("seeds", seeds, section.get("seeds"))):
                if not isinstance(own, dict) or own.keys() != listed.keys() or not all(
                        _same(listed[k], own[k]) for k in listed):
                    raise ValueError(
                        f"{os.path.join(self._dataset_path, 'index.jsonl')}: sample {self.index}'s {what} "
                        f"{json.dumps(listed)[:200]} are not its folder's ({folder}/metadata.json: "
                        f"{json.dumps(own)[:200]}): index.jsonl was edited or damaged since it was written; "
                        "`spadgen dataset run` writes it again")
            self._runs[r] = run
        return self._runs[r]

    @property
    def run(self):
        """The sample's run folder (realisation 0) as a spadgen.Run; SampleNotDoneError unless done."""
        return self._open(0)

    @property
    def repeats(self):
        """The runs of realisations 1, 2, ... of the temporal noise (the dataset file's "repeats" - 1 of them:
        the same light and ground truth, counts from noise seeds S + 1, ...); [] without repeats."""
        return [self._open(r) for r in range(1, len(self.repeat_folders) + 1)]

    @property
    def realisations(self):
        """Every realisation's run, realisation r at position r: [run] + repeats."""
        return [self.run] + self.repeats


class Dataset:
    """A dataset folder's index, or a selection of it (select(), slicing): rows in index order."""

    def __init__(self, path, _spec=None, _rows=None, _all=None):
        self.path = os.fspath(path)
        if _spec is not None:  # a view of another Dataset
            self.spec, self.index, self._all = _spec, _rows, _all
            return
        spec_path = os.path.join(self.path, "dataset.json")
        if not os.path.isfile(spec_path):
            hint = ""
            if os.path.isfile(os.path.join(self.path, "metadata.json")):
                hint = " it is a run folder: spadgen.open_run reads it;"
            elif not os.path.isdir(self.path):
                hint = " no such folder;"
            raise FileNotFoundError(f"{self.path}: not a spadgen dataset folder (no dataset.json;{hint} "
                                    "`spadgen dataset run FILE -o DIR` writes one)")
        # (the remedy is the program's: `spadgen dataset run` refuses a folder whose dataset.json is damaged, as it
        # says which dataset the folder holds)
        remedy = ("it says which dataset file the folder holds, and `spadgen dataset run` refuses the folder without "
                  "it: restore it, or generate the dataset into another folder")
        with open(spec_path, encoding="utf-8") as f:
            try:
                self.spec = load_json(f)
            except ValueError as e:
                raise ValueError(f"{spec_path}: not valid JSON ({e}); `spadgen dataset run` writes it whole, so it was "
                                 f"damaged afterwards; {remedy}") from e
        if not isinstance(self.spec, dict):
            raise ValueError(f"{spec_path}: JSON, but not an object (`spadgen dataset run` writes one): it was damaged "
                             f"afterwards; {remedy}")
        # what the parameters' names are read from (a "random" of null was a TypeError)
        for key in ("grid", "random"):
            if not isinstance(self.spec.get(key, {}), dict):
                raise ValueError(f"{spec_path}: {key} is {json.dumps(self.spec[key])[:40]}, not an object (`spadgen dataset "
                                 f"run` writes one): it was damaged afterwards; {remedy}")
        index_path = os.path.join(self.path, "index.jsonl")
        if not os.path.isfile(index_path):
            if _runs_on(self.path):
                raise FileNotFoundError(f"{self.path}: a dataset folder without index.jsonl: the first `spadgen dataset "
                                        "run` into it is still running (the last run on the folder to end writes the "
                                        "index); wait for it to finish")
            raise FileNotFoundError(f"{self.path}: a dataset folder without index.jsonl: the first `spadgen dataset run` "
                                    "into it was killed (the last run on the folder to end writes the index, also when "
                                    "stopped by SIGINT or SIGTERM); run it again to finish")
        with open(index_path, encoding="utf-8") as f:
            self.index = []
            number = 0  # (rows as _check_index counts them: blank lines are none)
            for line in f:
                if not line.strip():
                    continue
                number += 1
                try:
                    self.index.append(json.loads(line))
                except json.JSONDecodeError as e:  # (line by line: its own "line 1" named no row)
                    raise ValueError(f"{index_path} row {number}: not valid JSON ({e.msg} at column {e.colno}); "
                                     "`spadgen dataset run` writes it whole, so it was damaged afterwards: run the "
                                     "dataset again to write it") from e
        _check_index(self.index, index_path)
        _check_rows_against_spec(self.index, self.spec, self.path, index_path)
        self._all = self.index

    def _view(self, rows):
        return Dataset(self.path, _spec=self.spec, _rows=list(rows), _all=self._all)

    def __repr__(self):
        counts = self.status_counts()
        parts = ", ".join(f"{n} {s}" for s, n in counts.items() if n)
        return f"Dataset({self.path!r}, {len(self)} samples" + (f": {parts})" if parts else ")")

    # ---- what the dataset is ----------------------------------------------------------------------------

    @property
    def card(self):
        """dataset.md, the dataset card (Markdown)."""
        path = os.path.join(self.path, "dataset.md")
        if not os.path.isfile(path):
            raise FileNotFoundError(f"{path}: missing (the last `spadgen dataset run` to end writes it with the index): "
                                    "run the dataset again to write it (with nothing left to generate, it writes only the "
                                    "index and the card)")
        with open(path, encoding="utf-8") as f:
            return f.read()

    @property
    def parameter_keys(self):
        """What varies between samples, in index.csv's column order: "scene", the grid keys, the random keys."""
        return ["scene"] + list(self.spec.get("grid", {})) + list(self.spec.get("random", {}))

    def parameter_kind(self, key):
        """The type of a parameter over every sample of the dataset (not only this selection): "bool", "int",
        "float", "str" or "object" (arrays, mixed types); it decides the column's dtype in table()."""
        if key not in self.parameter_keys:
            raise KeyError(f"{self.path}: no parameter {key!r}; the parameters are {', '.join(self.parameter_keys)}")
        return _kind([r["parameters"].get(key) for r in self._all])

    @property
    def numeric_parameter_keys(self):
        """The parameters whose values are numbers (or booleans) in every sample, in parameter_keys' order."""
        return [k for k in self.parameter_keys if self.parameter_kind(k) in ("bool", "int", "float")]

    @property
    def indices(self):
        """(S,) int64: the dataset index of each sample of this selection."""
        return np.array([r["index"] for r in self.index], np.int64)

    def status_counts(self):
        """{"done": n, "failed": n, "stale": n, "missing": n, "damaged": n} over this selection."""
        out = dict.fromkeys(STATUSES, 0)
        for r in self.index:
            out[r["status"]] = out.get(r["status"], 0) + 1
        return out

    # ---- samples ----------------------------------------------------------------------------------------

    def __len__(self):
        return len(self.index)

    def __iter__(self):
        return (Sample(self, r) for r in self.index)

    def __getitem__(self, i):
        """ds[i]: the i-th sample of this selection (not dataset index i: sample(i) is that); ds[a:b] a selection."""
        if isinstance(i, slice):
            return self._view(self.index[i])
        given, i = i, _position(i)
        if i is None:
            raise TypeError(f"{self.path}: ds[{given!r}]; expected a position in this selection (an int) or a slice")
        if not -len(self.index) <= i < len(self.index):
            raise IndexError(f"{self.path}: ds[{i}] is past this selection of {len(self.index)} samples (positions "
                             f"0 to {len(self.index) - 1}; sample(index) finds a sample by its dataset index)")
        return Sample(self, self.index[i])

    def sample(self, index):
        """The sample of dataset index ``index`` (KeyError when this selection does not hold it)."""
        for r in self.index:
            if r["index"] == index:
                return Sample(self, r)
        raise KeyError(f"{self.path}: sample {index} is not in this selection of {len(self)} samples")

    def select(self, status=None, where=None, **parameters):
        """The samples of this selection that match everything given:

        status      "done", "failed", "stale", "missing", "damaged", or several of them in a list or tuple;
        where       a function of the index row (a dict as index.jsonl has it) returning true to keep it;
        **parameters  parameter key = value, equal by ==, a JSON array equal to a list, tuple or NumPy array; a dotted key
                    as select(**{"laser.average_power_mW": 2}), or with "__" for each dot: laser__average_power_mW=2.
        """
        keep = list(self.index)
        if status is not None:
            try:  # (a text, or any iterable of them: a list, a NumPy array, a pandas Series)
                wanted = (status,) if isinstance(status, str) else tuple(status)
            except TypeError:
                raise TypeError(f"select: status={status!r}; expected one of {', '.join(STATUSES)} or a list of them") from None
            unknown = [s for s in wanted if s not in STATUSES]
            if unknown:
                raise ValueError(f"unknown status {unknown}; a sample is one of {', '.join(STATUSES)}")
            keep = [r for r in keep if r["status"] in wanted]
        for name, value in parameters.items():
            key = name
            if key not in self.parameter_keys and name.replace("__", ".") in self.parameter_keys:
                key = name.replace("__", ".")
            if key not in self.parameter_keys:
                raise ValueError(f"{self.path}: no parameter {name!r}; the parameters are {', '.join(self.parameter_keys)} "
                                 "(a dot may be written __)")
            if isinstance(value, np.ndarray):  # an array's values as a list (an array matched nothing, silently)
                value = value.tolist()
            keep = [r for r in keep if _same(r["parameters"].get(key), value)]
        if where is not None:
            keep = [r for r in keep if where(r)]
        return self._view(keep)

    # ---- the table --------------------------------------------------------------------------------------

    @property
    def columns(self):
        """The table's columns: index.csv's."""
        return (["index", "status", "folder"] + self.parameter_keys + [c for c, _ in _SEEDS] + ["sample_hash", "bytes"]
                + list(self._summary_keys()) + ["error", "warnings"])

    def _summary_keys(self):
        keys = list(SUMMARY_COLUMNS)
        for r in self._all:
            keys += [k for k in (r.get("ground_truth") or {}) if k not in keys]
        return keys

    def table(self, columns=None):
        """The index as a dict of (S,) NumPy arrays, one per column (index.csv's columns, in its order):

        index, seed, seed_light, seed_chip, seed_noise   int64
        status, folder, sample_hash, error               str ("" where the row has none)
        each parameter   by its kind over the whole dataset: bool, int64, float64, str, or object (arrays)
        bytes and the ground-truth summary (hit_fraction, range_min_m, range_max_m, meshes_in_view,
                         max_layer_count, objects_in_view, max_object_count, multi_object_fraction,
                         objects_detectable, detectable_fraction, laser_photons_per_pulse)   float64, NaN
                         where the sample is not done (the two detectable columns also where it has no
                         labels.exr: 2D runs)
        warnings         float64: how many warnings the sample's run gave (Sample.warnings lists them), NaN
                         where the sample is not done
        """
        names = self.columns if columns is None else list(columns)
        params = set(self.parameter_keys)
        summary = set(self._summary_keys())
        seeds = dict(_SEEDS)
        out = {}
        for c in names:
            if c == "index":
                out[c] = self.indices
            elif c in ("status", "folder", "sample_hash", "error"):
                out[c] = np.array([r.get(c) or "" for r in self.index], dtype=str)
            elif c in seeds:
                out[c] = np.array([r["seeds"][seeds[c]] for r in self.index], np.int64)
            elif c == "bytes":
                out[c] = np.array([r.get("bytes", math.nan) for r in self.index], np.float64)
            elif c == "warnings":
                out[c] = np.array([len(r["warnings"]) if "warnings" in r else math.nan for r in self.index], np.float64)
            elif c in summary:
                out[c] = np.array([(r.get("ground_truth") or {}).get(c, math.nan) for r in self.index], np.float64)
            elif c in params:
                values = [r["parameters"].get(c) for r in self.index]
                kind = self.parameter_kind(c)
                if kind in ("bool", "int", "float", "str"):
                    out[c] = np.array(values, dtype={"bool": bool, "int": np.int64, "float": np.float64, "str": str}[kind])
                else:
                    out[c] = np.empty(len(values), object)
                    for i, v in enumerate(values):  # an array parameter stays one list per row
                        out[c][i] = v
            else:
                raise KeyError(f"{self.path}: no column {c!r}; the columns are {', '.join(self.columns)}")
        return out

    def to_pandas(self, columns=None):
        """table() as a pandas DataFrame (pandas is not a dependency of spadgen: ImportError without it)."""
        try:
            import pandas
        except ImportError as e:
            raise ImportError("Dataset.to_pandas needs pandas (Debian 12: apt-get install python3-pandas); "
                              "Dataset.table() gives the same columns as NumPy arrays") from e
        return pandas.DataFrame(self.table(columns))


def open_dataset(path):
    """Opens a dataset folder (reads dataset.json and index.jsonl)."""
    return Dataset(path)
