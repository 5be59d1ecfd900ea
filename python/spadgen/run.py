"""One run folder (what ``spadgen run SCENE.json -o DIR`` writes), read lazily.

    run = spadgen.open_run("out/multi_object")
    run.counts                      # (K, H, W) uint8/uint16 memory map of counts.npy (zarr.Array of counts.zarr)
    run.ground_truth["range"]       # (H, W) float32 channel of ground_truth.exr
    run.gate_profile(300, 120)      # Profile of pixel x=300, y=120: gate_ns, values (its counts), x, y
    run.points(frame="world")       # (H, W, 3) ground-truth surface points

Nothing is read until it is used: metadata.json on opening, a stack when first indexed (a NumPy memory
map, or a zarr.Array for a run with outputs.storage = zarr: the same indexing, the same values), an EXR
image when its first channel is asked for. The folder's layout is docs/outputs.md.
"""
from __future__ import annotations

import json
import math
import numbers
import operator
import os
import re
import stat
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from . import camera as _camera
from .exr import ExrFile


def load_json(f):
    """json.load as spadgen's programs read JSON (nlohmann): NaN, Infinity and numbers beyond a double (1e999)
    are errors (json.load takes them, as non-finite floats: intrinsics of 1e999 reached the rays); a ValueError."""
    def constant(name):
        raise ValueError(f"{name} is not a JSON number")

    def real(text):
        v = float(text)
        if v in (float("inf"), float("-inf")):
            raise ValueError(f"the number {text[:32]} is beyond a double")
        return v
    return json.load(f, parse_constant=constant, parse_float=real)

__all__ = ["Run", "open_run", "unpack_frames", "TimeAxis", "Profile", "Layers"]

C = 299792458.0  # speed of light in vacuum, m/s


def unpack_frames(packed, width):
    """Binary frames (..., H, ceil(W / 8)) uint8, as frames.npy stores them, to (..., H, W) uint8 of 0 and 1.

    Pixel x of a row is bit x % 8 of byte x // 8, least significant bit first (NumPy's default bit order,
    "big", would mirror every group of 8 pixels); the bits beyond W in the last byte are dropped."""
    packed = np.asarray(packed)
    if packed.dtype != np.uint8:
        raise TypeError(f"packed frames must be uint8, got {packed.dtype}")
    if packed.shape[-1] != (width + 7) // 8:
        raise ValueError(f"a row of {width} pixels takes {(width + 7) // 8} bytes, the array's rows have {packed.shape[-1]}")
    return np.unpackbits(packed, axis=-1, count=width, bitorder="little")


@dataclass(frozen=True)
class TimeAxis:
    """The rendered time window of transient.npy: bin i covers [start_s + i w, start_s + (i + 1) w)."""
    start_s: float
    bin_width_s: float
    bins: int
    period_s: float  # the laser period: later returns fold into the next period

    @property
    def end_s(self):
        return self.start_s + self.bins * self.bin_width_s

    def bin_starts_s(self):
        return self.start_s + np.arange(self.bins) * self.bin_width_s

    def bin_centres_s(self):
        return self.start_s + (np.arange(self.bins) + 0.5) * self.bin_width_s


@dataclass(frozen=True)
class Profile:
    """A pixel's gate profile: ``values[k]`` counts (or expected counts) at gate position ``gate_ns[k]``."""
    gate_ns: np.ndarray
    values: np.ndarray
    x: int
    y: int


@dataclass(frozen=True)
class Layers:
    """Every surface along each pixel's primary ray (ground_truth.exr), nearest first.
    ``count`` (H, W) int32; ``range`` (L, H, W) float32 metres (+inf beyond a pixel's count);
    ``transmittance`` (L, H, W) float32, the fraction of light that reaches that surface."""
    count: np.ndarray
    range: np.ndarray
    transmittance: np.ndarray


@dataclass(frozen=True)
class ObjectSlots:
    """The objects along each pixel's primary ray (ground_truth.exr; docs/outputs.md), in the order the ray
    meets them, J = metadata.json's ``ground_truth_objects`` slots. ``first`` (H, W) int32: the first hit's
    object id, -1 on a miss; ``count`` (H, W) int32: objects along the ray. Per slot, (J, H, W): ``id`` int32
    (an index into ``Run.objects``, -1 for an unused slot), ``range`` float32 metres of the object's first
    surface (+inf unused), ``transmittance`` float32 fraction reaching it, ``laser`` float32 photons per
    pulse the object returns directly (0 unused), ``path`` float32 metres, the optical path of that direct return,
    laser to object to camera (it arrives at laser.emission_delay + path / c; +inf unused). ``direct_other_laser`` and ``indirect_laser`` (H, W)
    float32: the rest of laser.exr. ``laser``, ``direct_other_laser`` and ``indirect_laser`` are None when the run
    traced no laser (a 2D run without acquisition.intensity.laser_on; metadata.json ``model``). From labels.exr (gate sweep only; None in a 2D run, which writes none):
    ``edge_counts`` and ``edge_snr`` (J, H, W) float32, ``detectable`` (J, H, W) bool."""
    first: np.ndarray
    count: np.ndarray
    id: np.ndarray
    range: np.ndarray
    transmittance: np.ndarray
    laser: np.ndarray
    direct_other_laser: np.ndarray
    indirect_laser: np.ndarray
    edge_counts: np.ndarray = None
    edge_snr: np.ndarray = None
    path: np.ndarray = None
    detectable: np.ndarray = None


@dataclass(frozen=True)
class Detections:
    """What ``spadgen reconstruct`` found in each pixel's gate profile (detections_<detector>.exr;
    docs/detection.md). ``count`` (H, W) int32; per slot, (M, H, W) float32 in increasing range: ``range``
    metres (NaN in an empty slot), ``gate`` the fractional gate index of the edge, ``amplitude`` detections
    per frame the return adds, ``score`` its z. ``detector``: the detector and its parameters, ``source``:
    the run it read (the file's header)."""
    count: np.ndarray
    range: np.ndarray
    gate: np.ndarray
    amplitude: np.ndarray
    score: np.ndarray
    detector: dict
    source: dict


def _dataset_of_samples(samples):
    """The dataset folder whose samples/ is the folder `samples` (as `spadgen dataset run` lays it out), or None."""
    samples = os.path.abspath(samples)
    parent = os.path.dirname(samples)
    return parent if os.path.basename(samples) == "samples" and os.path.isfile(os.path.join(parent, "dataset.json")) else None


def _not_a_run_why(path):
    """Why a folder without metadata.json is not a run, and where the runs are when it holds some."""
    if not os.path.exists(path):
        return "no such folder"
    if not os.path.isdir(path):
        return "not a folder"
    if os.path.isfile(os.path.join(path, "dataset.json")):
        return ("a dataset folder, not a run folder: spadgen.open_dataset() opens it (its samples' runs are in "
                "samples/)")
    repeats = sorted(n for n in os.listdir(path) if os.path.isfile(os.path.join(path, n, "metadata.json")))
    if repeats:
        dataset = _dataset_of_samples(path)
        where = (f"a dataset's samples: spadgen.open_dataset({dataset!r}) opens the dataset" if dataset
                 else "spadgen sense --repeats writes one per realisation")
        return (f"not a run folder itself; it holds {len(repeats)} run folder(s): {', '.join(repeats[:4])}"
                + (", ..." if len(repeats) > 4 else "") + f" ({where})")
    return "not a spadgen run folder (no metadata.json; a run writes it last, so a folder without it is incomplete)"


class RunChangedError(RuntimeError):
    """The run folder was replaced (a newer run, or a dataset run regenerating its sample) since the Run was opened:
    what it read before and what it would read after come from two versions."""


def _identity(path):
    """Which file `path` (or an open file's descriptor) is: a run folder replaced whole has a new metadata.json."""
    st = os.fstat(path) if isinstance(path, int) else os.stat(path)
    return st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns


# The dtypes spadgen writes a Zarr array in (writers/zarr.cpp reads no other).
_ZARR_DTYPES = ("<f4", "<f8", "|u1", "<u1", "<u2", "<i4", "<i8")


def _check_zarray(path):
    """The store's .zarray as parsed, checked as the program's Zarr reader (writers/zarr.cpp) checks it: format 2,
    C order (an "F" was read as C order without a word), no filters, "." separators, a dtype spadgen writes, a
    shape and chunks of positive integers of one length, Blosc or no compressor, a number or null fill value (or
    "NaN", "Infinity", "-Infinity" for floats, as the Zarr v2 specification writes them; spadgen's float stores
    have "NaN").
    A ValueError naming the store and the field otherwise; None when there is no readable .zarray (zarr reports
    that itself)."""
    try:
        with open(os.path.join(path, ".zarray"), "rb") as f:
            z = json.load(f)
    except (OSError, ValueError):
        return None

    def bad(what):
        return ValueError(f"{path}: {what}; spadgen writes its Zarr stores whole, so .zarray was damaged or edited after "
                          "the run published it")

    if not isinstance(z, dict):
        raise bad(".zarray is not a JSON object")
    for key in ("zarr_format", "order", "dtype", "shape", "chunks", "compressor", "fill_value"):
        if key not in z:
            raise bad(f".zarray has no {key!r}")
    if z["zarr_format"] != 2 or isinstance(z["zarr_format"], bool):
        raise bad(f".zarray's zarr_format is {json.dumps(z['zarr_format'])[:40]}, not 2")
    if z["order"] != "C":
        raise bad(f".zarray's order is {json.dumps(z['order'])[:40]}: only C order is supported (spadgen writes C)")
    if z.get("filters") not in (None, []):
        raise bad(f".zarray has filters ({json.dumps(z['filters'])[:60]}): filters are not supported (spadgen writes none)")
    if z.get("dimension_separator", ".") != ".":
        raise bad(f".zarray's dimension_separator is {json.dumps(z['dimension_separator'])[:40]}: only '.' is supported")
    if z["dtype"] not in _ZARR_DTYPES:
        raise bad(f".zarray's dtype {json.dumps(z['dtype'])[:40]} is not one spadgen writes ({', '.join(_ZARR_DTYPES)})")
    for key in ("shape", "chunks"):
        v = z[key]
        if not (isinstance(v, list) and v and all(isinstance(e, int) and not isinstance(e, bool) and e >= (key == "chunks")
                                                  for e in v)):
            raise bad(f".zarray's {key} {json.dumps(v)[:60]} is not a list of {'positive' if key == 'chunks' else 'non-negative'} integers")
    if len(z["chunks"]) != len(z["shape"]):
        raise bad(f".zarray's chunks {z['chunks']} and shape {z['shape']} differ in length")
    c = z["compressor"]
    if c is not None and not (isinstance(c, dict) and c.get("id") == "blosc"):
        raise bad(f".zarray's compressor {json.dumps(c)[:60]}: only Blosc (or none) is supported")
    f = z["fill_value"]
    floats = z["dtype"] in ("<f4", "<f8")
    if f is not None and (isinstance(f, bool) or not isinstance(f, (int, float))) and not (
            floats and f in ("NaN", "Infinity", "-Infinity")):
        raise bad(f".zarray's fill_value {json.dumps(f)[:40]} is not a number"
                  + (', "NaN", "Infinity" or "-Infinity"' if floats else ""))
    # a value of the dtype, as the program's reader asks (writers/zarr.cpp): an integer in an integer dtype's
    # range, a float dtype's number within its range (zarr converts one outside regardless: -5 read as 251)
    if isinstance(f, (int, float)) and not isinstance(f, bool):
        dt = np.dtype(z["dtype"])
        if floats:
            if (isinstance(f, int) or math.isfinite(f)) and abs(f) > float(np.finfo(dt).max):
                raise bad(f".zarray's fill_value {json.dumps(f)[:40]} is not a number in the range of dtype {z['dtype']}")
        elif not isinstance(f, int) or not np.iinfo(dt).min <= f <= np.iinfo(dt).max:
            raise bad(f".zarray's fill_value {json.dumps(f)[:40]} is not an integer in the range of dtype {z['dtype']}")
    return z


_CHECK_BLOCK_BYTES = 64 << 20  # Run.counts's check reads at most about this much at a time


def _zarr_store(path, z=None, check=None):
    """A Zarr directory store whose missing chunk is an error naming it: a store without a fill value would
    otherwise read it as uninitialised memory (spadgen writes every chunk: one missing is damage). A Blosc
    chunk shorter or longer than its header says (cut short by a full disk or a copy) is an error naming it
    too, where Blosc's own says only "error during blosc decompression: -1"; so is a chunk that decodes to
    another size than .zarray's chunks of its dtype (z: the .zarray checked by _check_zarray; a dtype edited
    was "cannot reshape array of size ..."). check: called before and after each chunk is read (Run.check_unchanged): zarr
    reads a chunk by its path when it is indexed, so a store opened before its run folder was replaced read the new
    run's chunks silently (a verifier's find), where a .npy's memory map keeps the version it opened."""
    import re
    import zarr

    blosc = isinstance(z, dict) and (z.get("compressor") or {}).get("id") == "blosc"
    nbytes = int(np.prod(z["chunks"])) * np.dtype(z["dtype"]).itemsize if isinstance(z, dict) else None

    class StrictStore(zarr.storage.DirectoryStore):
        _chunk = re.compile(r"^\d+(\.\d+)*$")

        def __getitem__(self, key):
            chunk = self._chunk.match(key.rsplit("/", 1)[-1])
            if check is not None and chunk:
                check()
            try:
                value = super().__getitem__(key)
            except KeyError:
                if self._chunk.match(key.rsplit("/", 1)[-1]):
                    raise FileNotFoundError(f"{os.path.join(path, key)}: a chunk of this Zarr store is missing (spadgen "
                                            "writes every chunk: the store was damaged after the run published it): "
                                            "restore it, or run the scene again") from None
                raise
            if blosc and self._chunk.match(key.rsplit("/", 1)[-1]):
                # Blosc's 16-byte header: bytes 12-15 hold the chunk's compressed size, little-endian.
                stated = int.from_bytes(value[12:16], "little") if len(value) >= 16 else None
                if stated != len(value):
                    raise OSError(f"{os.path.join(path, key)}: a chunk of this Zarr store holds {len(value)} bytes, "
                                  + (f"its Blosc header says {stated}" if stated is not None else "less than a Blosc header")
                                  + ": it was cut short or damaged after the run published it; restore it, or run the "
                                  "scene again")
            if nbytes is not None and self._chunk.match(key.rsplit("/", 1)[-1]):
                # Blosc's bytes 4-7: the chunk's decoded size; an uncompressed chunk is that size itself.
                decoded = int.from_bytes(value[4:8], "little") if blosc else len(value)
                if decoded != nbytes:
                    raise ValueError(f"{os.path.join(path, key)}: a chunk of this Zarr store decodes to {decoded} bytes, "
                                     f"but .zarray's chunks {z['chunks']} of {z['dtype']} take {nbytes}: .zarray or the "
                                     "chunk was damaged or edited after the run published it; restore it, or run the "
                                     "scene again")
            if check is not None and chunk:
                check()  # (and after: the folder replaced while the chunk was read)
            return value

    return StrictStore(path)


class Run:
    """A run folder. Every output is an attribute; asking for a file the run did not write raises
    FileNotFoundError naming the scene-file key that writes it (never None).

    A run folder may be replaced whole while it is open (spadgen publishes a new run, or a dataset run
    regenerates a stale sample, by swapping folders): the memory maps of .npy stacks keep reading the version
    they opened, an EXR image whose header was read before refuses to decode the newer file (ExrError), and
    Zarr stores are read chunk by chunk from the folder. check_unchanged()
    raises RunChangedError once the folder was replaced, and so does every file the Run opens after that (it
    would be the newer run's, beside this one's metadata); RunDataset and DatasetSamples call it around every
    item."""

    # The scene-file key that makes a run write an optional file, for the error message.
    _WRITTEN_BY = {"transient.npy": "outputs.transient", "transient_indirect.npy": "render.split_direct_indirect "
                   "with outputs.transient", "frames.npy": "outputs.frames", "ground_truth.exr": "outputs.ground_truth",
                   "expected_counts.npy": "outputs.expected_counts", "counts.npy": "outputs.counts",
                   "detection_rate.npy": "outputs.detection_rate",
                   "intensity.exr": "acquisition.mode = intensity",
                   "labels.exr": "acquisition.mode = gate_sweep with outputs.ground_truth",
                   "laser.exr": "a gate sweep, or in the intensity mode with acquisition.intensity.laser_on, "
                   "outputs.transient, or outputs.light with render.window_start_ns: else the laser is not traced"}

    def __init__(self, path):
        self.path = os.fspath(path)
        meta = os.path.join(self.path, "metadata.json")
        if not os.path.isfile(meta):
            raise FileNotFoundError(f"{self.path}: " + _not_a_run_why(self.path))
        try:
            with open(meta, encoding="utf-8") as f:
                identity = _identity(f.fileno())  # of the file read (a swap between reading and a stat would pass)
                self.metadata = load_json(f)
        except (UnicodeDecodeError, ValueError) as e:
            raise ValueError(f"{meta}: not valid JSON ({e}); spadgen publishes a run folder whole, so the file was damaged "
                             "or cut short afterwards: restore it, or run the scene again") from e
        if not isinstance(self.metadata, dict) or not isinstance(self.metadata.get("files"), list):
            raise ValueError(f"{meta}: not a spadgen run's metadata (no list of files)")
        self.files = list(self.metadata["files"])
        self._cache = {}
        self._identity = identity
        self._check_metadata(meta)

    def _check_metadata(self, meta):
        """What every reader of the run takes from metadata.json, where present, of the types a run writes: a
        damaged one is named with the key (it was a bare KeyError, ValueError or TypeError from wherever it was
        read). A key that is absent is named where it is read (a run of another spadgen version)."""
        m = self.metadata

        def bad(key, what):
            return ValueError(f"{meta}: {key} {what}; spadgen writes metadata.json whole, so it was damaged or edited "
                              "afterwards: restore it, or " + self._remedy())

        def section(name):
            if name in m and not isinstance(m[name], dict):
                raise bad(name, "is not an object")
            return m.get(name, {})

        def whole(name, key, least=1):
            v = section(name).get(key, least)
            if isinstance(v, bool) or not isinstance(v, int) or not least <= v <= 1 << 20:
                raise bad(f"{name}.{key}", f"is {json.dumps(v)[:40]}, not an integer in [{least}, {1 << 20}]")

        if not all(isinstance(f, str) for f in self.files):
            raise bad("files", "holds an entry that is not a file name")
        for name in ("units", "seeds", "dataset"):
            section(name)
        if "objects" in m and not isinstance(m["objects"], list):
            raise bad("objects", "is not a list")
        for key in ("start_ns", "bin_width_ps", "laser_period_ns"):
            v = section("time_axis").get(key, 0)
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise bad(f"time_axis.{key}", f"is {json.dumps(v)[:40]}, not a number")
        whole("time_axis", "bins", 0)  # (0: a 2D run renders no transient)
        if "counts_dtype" in m and m["counts_dtype"] not in ("uint8", "uint16"):
            raise bad("counts_dtype", f"is {json.dumps(m['counts_dtype'])[:40]}, not \"uint8\" or \"uint16\"")
        if "seed" in m and (isinstance(m["seed"], bool) or not isinstance(m["seed"], int)):
            raise bad("seed", f"is {json.dumps(m['seed'])[:40]}, not an integer")
        whole("image", "width")
        whole("image", "height")
        crop = section("image").get("crop_in_sensor", [0, 0, 0, 0])
        if not (isinstance(crop, list) and len(crop) == 4 and all(isinstance(v, int) and not isinstance(v, bool) for v in crop)):
            raise bad("image.crop_in_sensor", "is not 4 integers (x0, y0, width, height)")
        acq = section("acquisition")
        if "mode" in acq and acq["mode"] not in ("gate_sweep", "intensity"):
            raise bad("acquisition.mode", f"is {json.dumps(acq['mode'])[:40]}, not \"gate_sweep\" or \"intensity\"")
        whole("acquisition", "K")
        whole("acquisition", "frames_per_k")
        for key, mode in (("gate_positions_ns", "gate_sweep"), ("exposures_us", "intensity")):
            g = acq.get(key)
            if acq.get("mode") == mode and g is not None and not (
                    isinstance(g, list) and len(g) == acq.get("K", len(g)) and
                    all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in g)):
                raise bad(f"acquisition.{key}", "is not K numbers")
        for key, n in (("intrinsics", 3), ("camera_to_world", 4)):
            mat = section("camera").get(key, [[0] * n] * n)
            if not (isinstance(mat, list) and len(mat) == n and all(
                    isinstance(r, list) and len(r) == n and
                    all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in r) for r in mat)):
                raise bad(f"camera.{key}", f"is not a {n} x {n} matrix of finite numbers")
        for key in ("ground_truth_layers", "ground_truth_objects"):
            v = m.get(key, 0)
            if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= 1 << 20:
                raise bad(key, f"is {json.dumps(v)[:40]}, not an integer in [0, {1 << 20}]")

    def _remedy(self):
        """How to make the run's files again: its scene, or for a dataset's sample the dataset run (which finds
        the sample damaged and generates it again)."""
        if isinstance(self.metadata.get("dataset"), dict):
            # the dataset folder, where the sample sits in its samples/ (as it was written); else said as DIR
            folder = _dataset_of_samples(os.path.dirname(os.path.abspath(self.path)))
            return (f"run `spadgen dataset run {self.metadata['dataset'].get('dataset_file', 'DATASET.json')} -o "
                    f"{folder or 'DIR'}` on its dataset folder again (the sample is damaged: it is generated again)")
        return "run the scene again"

    def unchanged(self):
        """True while the folder is the one this Run opened (its metadata.json is the same file)."""
        try:
            return _identity(os.path.join(self.path, "metadata.json")) == self._identity
        except OSError:
            return False

    def check_unchanged(self):
        """Raises RunChangedError when the folder was replaced since this Run opened it."""
        if not self.unchanged():
            raise RunChangedError(f"{self.path}: the run folder was replaced since it was opened (a newer run, or a "
                                  "dataset run regenerating its sample, published another version): what was read from "
                                  "it would mix the two; open it again")

    def __repr__(self):
        return f"Run({self.path!r}, {self.width} x {self.height}, {self.mode}, K = {self.K})"

    def _meta(self, key):
        """metadata.json's `key`; a run of another spadgen version without it is named as such."""
        if key not in self.metadata:
            from ._version import __version__
            raise KeyError(f"{os.path.join(self.path, 'metadata.json')} has no {key!r}: the run was written by spadgen "
                           f"{self.metadata.get('spadgen_version', '(unknown)')}, and this package reads runs of spadgen "
                           f"{__version__}: run the scene again with it")
        return self.metadata[key]

    def _required(self, section, key=None):
        """metadata.json's section.key (or top-level `section` without a key), which every run writes: a file
        without it was edited (it was a bare KeyError naming the key alone), named as such."""
        if key is None:
            found, name = section in self.metadata, section
        else:
            found, name = isinstance(self.metadata.get(section), dict) and key in self.metadata[section], f"{section}.{key}"
        if not found:
            raise ValueError(f"{os.path.join(self.path, 'metadata.json')}: has no {name}, which every run writes: "
                             "it was damaged or edited after the run published it: restore it, or " + self._remedy())
        return self.metadata[section] if key is None else self.metadata[section][key]

    # ---- what the run is --------------------------------------------------------------------------------

    @property
    def width(self):
        return int(self._required("image", "width"))

    @property
    def height(self):
        return int(self._required("image", "height"))

    @property
    def crop(self):
        """(x0, y0, width, height) of the images in sensor pixels."""
        return tuple(int(v) for v in self._required("image", "crop_in_sensor"))

    @property
    def units(self):
        return dict(self._required("units"))

    @property
    def seed(self):
        """The scene file's `seed`: the default of every stream (a dataset's sample, its realisations and a
        sense's repeats share it); the streams' own are ``seeds``."""
        return self._required("seed")

    @property
    def seeds(self):
        """The seed each random stream used: ``{"light": ..., "chip": ..., "noise": ...}`` (metadata.json
        ``seeds``; a realisation's ``noise`` is its own)."""
        return dict(self._meta("seeds"))

    @property
    def spadgen_version(self):
        return self._required("spadgen_version")

    @property
    def acquisition(self):
        self._required("acquisition", "mode")
        return self.metadata["acquisition"]

    @property
    def mode(self):
        """The acquisition mode: "gate_sweep" or "intensity"."""
        return self._required("acquisition", "mode")

    @property
    def K(self):
        """Gate positions (gate sweep) or exposures (intensity mode): the first axis of the (K, H, W) stacks."""
        return int(self._required("acquisition", "K"))

    @property
    def frames_per_k(self):
        return int(self._required("acquisition", "frames_per_k"))

    @property
    def gate_positions_s(self):
        """(K,) float64 gate positions in seconds after the laser trigger (gate sweep only)."""
        if self.mode != "gate_sweep":
            raise ValueError(f"{self.path}: a 2D intensity run has no gate positions (exposures_s has its exposures)")
        return np.asarray(self._required("acquisition", "gate_positions_ns"), np.float64) * 1e-9

    @property
    def gate_positions_ns(self):
        return self.gate_positions_s * 1e9

    @property
    def exposures_s(self):
        """(K,) float64 exposure times in seconds (intensity mode only)."""
        if self.mode != "intensity":
            raise ValueError(f"{self.path}: a gate-sweep run has no exposures (gate_positions_s has its gate positions)")
        return np.asarray(self._required("acquisition", "exposures_us"), np.float64) * 1e-6

    @property
    def time_axis(self):
        a = {k: self._required("time_axis", k) for k in ("start_ns", "bin_width_ps", "bins", "laser_period_ns")}
        return TimeAxis(a["start_ns"] * 1e-9, a["bin_width_ps"] * 1e-12, int(a["bins"]), a["laser_period_ns"] * 1e-9)

    # ---- files ------------------------------------------------------------------------------------------

    def _file(self, name):
        """The file the run wrote for `name`: itself, or for a stack the same stack in the other container
        ("counts.npy" or "counts" names "counts.zarr" in a run with outputs.storage = zarr); None if none."""
        if name in self.files:
            return name
        stem = name[:-4] if name.endswith(".npy") else name[:-5] if name.endswith(".zarr") else name
        for ext in (".npy", ".zarr"):
            if stem + ext in self.files:
                return stem + ext
        return None

    def has(self, name):
        """Whether the run wrote the file (a name from metadata.json's files, e.g. "frames.npy"). A stack may
        be named in either container: has("counts.npy") is true for a run that wrote counts.zarr; an image
        without its extension too, as run[name] takes it: has("laser") is has("laser.exr"). What spadgen reconstruct
        writes into the folder is not the run's: run.detections() and run.hdr() read it."""
        return self._file(name) is not None or (not name.endswith((".exr", ".npy", ".zarr")) and name + ".exr" in self.files)

    def _require(self, name):
        found = self._file(name)
        if found is None:
            stem = name[:-4] if name.endswith(".npy") else name[:-5] if name.endswith(".zarr") else name
            why = self._WRITTEN_BY.get(stem + ".npy", self._WRITTEN_BY.get(name,
                                       "outputs.light" if name.startswith("light/") else None))
            # What `spadgen reconstruct` writes into the run folder is not the run's (metadata.json does not list
            # it): its reader is named (it was said not to be written, the file being there).
            derived = re.fullmatch(r"(detections_(\w+?)|hdr)(_noise_free)?\.exr", name)
            if derived:
                nf = "noise_free=True" if derived.group(3) else ""
                reader = (f"run.detections({', '.join(filter(None, [repr(derived.group(2)), nf]))})" if derived.group(2)
                          else f"run.hdr({nf})")
                written = "" if os.path.exists(os.path.join(self.path, name)) else (
                    f"; not written yet: spadgen reconstruct {self.path}"
                    + (f" --detector {derived.group(2)}" if derived.group(2) else "")
                    + (" --noise-free" if derived.group(3) else "") + " writes it")
                raise FileNotFoundError(f"{os.path.join(self.path, name)}: a file of spadgen reconstruct, not of the run "
                                        f"(metadata.json does not list it): {reader} reads it{written}")
            # A stack by its stem: a run writes it as .npy or as .zarr (outputs.storage), so an extension would mislead.
            shown = stem if name.endswith((".npy", ".zarr")) else name
            raise FileNotFoundError(f"{self.path}: this run did not write {shown}" + (f" (written with {why})" if why else "")
                                    + f"; it wrote {', '.join(self.files)}")
        return os.path.join(self.path, found)

    def array(self, name):
        """A stack of the run, read lazily: a .npy file as a read-only NumPy memory map, a Zarr store
        (outputs.storage = zarr) as a read-only zarr.Array (python3-zarr). Both index like NumPy arrays and
        return NumPy arrays (nothing is read until indexed); name it with or without its extension."""
        if not name.endswith((".npy", ".zarr")):
            name += ".npy"
        path = self._require(name)
        if path not in self._cache:
            if not os.path.exists(path):
                self.check_unchanged()  # (a newer run without the file: that, not damage)
                raise FileNotFoundError(f"{path}: listed in {os.path.join(self.path, 'metadata.json')} (files) but missing: "
                                        f"restore it, or {self._remedy()}")
            if path.endswith(".zarr"):
                try:
                    import zarr
                except ImportError as e:
                    raise ImportError(f"{path} is a Zarr store (outputs.storage = zarr): reading it needs zarr-python "
                                      "(Debian: python3-zarr)") from e
                try:
                    z = _check_zarray(path)
                except ValueError as e:
                    raise ValueError(f"{e}: restore it, or {self._remedy()}") from None
                try:
                    self._cache[path] = zarr.open_array(_zarr_store(path, z, self.check_unchanged), mode="r")
                except Exception as e:  # zarr's errors do not name the store
                    raise ValueError(f"{path}: not a readable Zarr array ({type(e).__name__}: {e}); damaged after the run "
                                     "published it: restore it, or " + self._remedy()) from e
            else:
                if not stat.S_ISREG(os.stat(path).st_mode):  # a FIFO would block the open for ever
                    raise ValueError(f"{path}: not a regular file; expected the run's .npy stack: restore it, or "
                                     + self._remedy())
                try:
                    self._cache[path] = np.load(path, mmap_mode="r")
                except ValueError as e:
                    raise ValueError(f"{path}: not a readable .npy file ({e}): cut short or damaged after the run published "
                                     "it: restore it, or " + self._remedy()) from e
            # A file opened after the folder was replaced is the newer run's, beside this Run's metadata and
            # whatever it read before: refused (it mixed the two without a word).
            if not self.unchanged():
                del self._cache[path]
                self.check_unchanged()
            # The (K, H, W) stacks are of the run's shape (a stack of another run copied in was read without a word)
            stem = os.path.basename(path).rsplit(".", 1)[0]
            if stem in ("counts", "expected_counts", "detection_rate"):
                want = (self.K, self.height, self.width)
                got = tuple(self._cache[path].shape)
                if got != want:
                    del self._cache[path]
                    raise ValueError(f"{path}: shape {got}, but metadata.json's (K, H, W) is {want}: the file is not this "
                                     "run's; restore it, or " + self._remedy())
            # and of the dtype the run writes them in (a float or wider counts file was read as counts)
            want = self._dtypes(stem)
            got = np.dtype(self._cache[path].dtype)
            if want and got not in want:
                del self._cache[path]
                raise ValueError(f"{path}: dtype {got.str}, but the run writes {stem} as "
                                 f"{' or '.join(str(d) for d in want)}: the file is not this run's or was damaged; restore "
                                 "it, or " + self._remedy())
        return self._cache[path]

    def _dtypes(self, stem):
        """The dtypes a run writes stack `stem` in (little-endian, as the program writes them); () if not known."""
        if stem == "counts":
            given = self.metadata.get("counts_dtype")  # (uint8 up to 255 frames per k, else uint16)
            return (np.dtype(given),) if given in ("uint8", "uint16") else (np.dtype(np.uint8), np.dtype("<u2"))
        if stem in ("expected_counts", "detection_rate", "transient", "transient_indirect"):
            return (np.dtype("<f4"),)
        if stem == "frames":
            return (np.dtype(np.uint8),)
        return ()

    def exr(self, name):
        """An .exr file of the run: channels by name, decoded on first access (spadgen.exr.ExrFile)."""
        if not name.endswith(".exr"):
            name += ".exr"
        if name not in self._cache:
            path = self._require(name)
            if not os.path.exists(path):
                self.check_unchanged()
                raise FileNotFoundError(f"{path}: listed in {os.path.join(self.path, 'metadata.json')} (files) but missing: "
                                        f"restore it, or {self._remedy()}")
            image = ExrFile(path)
            self.check_unchanged()  # opened after the folder was replaced: the newer run's (see array())
            self._check_image(image)
            self._cache[name] = image
        return self._cache[name]

    def _check_image(self, image):
        """An EXR image of the run is of its size (metadata.json's image) and, where its header says the crop
        (spadgen_crop), of its crop: a file of another run copied in was read without a word (images of two
        sizes mixed, or one crop's truth beside another's counts)."""
        if (image.width, image.height) != (self.width, self.height):
            raise ValueError(f"{image.path}: a {image.width} x {image.height} image, but metadata.json's image is "
                             f"{self.width} x {self.height}: the file is not this run's; restore it, or " + self._remedy())
        said = image.attributes.get("spadgen_crop")
        image_meta = self.metadata.get("image", {})
        if said is not None and "crop_in_sensor" in image_meta:
            try:
                crop = json.loads(said)
            except ValueError:
                crop = said
            if crop != list(self.crop):
                raise ValueError(f"{image.path}: its header's spadgen_crop is {said}, but metadata.json's "
                                 f"image.crop_in_sensor is {json.dumps(list(self.crop))}: the file is not this run's; "
                                 "restore it, or " + self._remedy())
        # The sensor maps and labels are of one chip (seeds.chip): another seed's run of the same crop was read
        # without a word, as the program's reconstruct read it.
        chip, ours = image.attributes.get("spadgen_chip_seed"), (self.metadata.get("seeds") or {}).get("chip")
        if (os.path.basename(image.path) in ("sensor_maps.exr", "labels.exr") and chip is not None
                and isinstance(ours, int) and not isinstance(ours, bool) and chip != str(ours)):
            raise ValueError(f"{image.path}: its header's spadgen_chip_seed is {chip[:24]}, but metadata.json's seeds.chip "
                             f"is {ours}: the file is of another chip, not this run's; restore it, or " + self._remedy())

    def __getitem__(self, name):
        """run["counts"], run["counts.npy"], run["ground_truth.exr"]: any stack or image by file name (a stack
        in either container)."""
        if name.endswith(".exr") or name + ".exr" in self.files:
            return self.exr(name)
        if name in self.files or name == "metadata.json":
            if not name.endswith((".npy", ".zarr")):
                raise ValueError(f"{self.path}: {name} is a file of the run but neither a stack nor an EXR image: read it "
                                 f"as a file ({os.path.join(self.path, name)}; metadata.json: run.metadata)")
        return self.array(name)

    @property
    def detection_rate(self):
        """(K, H, W) float32 lambda: mean avalanches per binary frame, noise-free (detection_rate.npy). Unlike
        expected counts it never saturates: expected counts = N (1 - exp(-lambda))."""
        return self.array("detection_rate.npy")

    @property
    def expected_counts(self):
        """(K, H, W) float32 noise-free expected counts N (1 - exp(-lambda)): expected_counts.npy when the run
        wrote it (outputs.expected_counts), else computed from detection_rate.npy (in memory, once)."""
        if not self.has("expected_counts.npy") and not self.has("detection_rate.npy"):
            msg = (f"{self.path}: this run wrote neither expected_counts nor detection_rate, from which expected counts "
                   "are computed (written with outputs.expected_counts or outputs.detection_rate)")
            if any(f.startswith("light/") for f in self.files):
                msg += (f"; it saved the light, from which `spadgen sense {self.path} --set outputs.detection_rate=true -o DIR` "
                        "writes the rates without rendering, bit for bit as a run would")
            raise FileNotFoundError(msg)
        if self.has("expected_counts.npy"):
            return self.array("expected_counts.npy")
        if "expected_counts (from detection_rate.npy)" not in self._cache:
            lam = np.asarray(self.detection_rate, np.float64)
            self._cache["expected_counts (from detection_rate.npy)"] = (self.frames_per_k * -np.expm1(-lam)).astype(np.float32)
        return self._cache["expected_counts (from detection_rate.npy)"]

    @property
    def counts(self):
        """(K, H, W) uint8 (up to 255 frames per k) or uint16 sampled counts. The first use checks every count
        is at most frames_per_k (a ValueError naming the file and the first pixel above it): one pass over the
        file, once per Run object (0.07 s for 360 MB of .npy from the page cache, 0.6 s from a Zarr store)."""
        counts = self.array("counts.npy")
        if "counts checked" not in self._cache:
            self._check_counts(counts)
            self._cache["counts checked"] = True
        return counts

    def _check_counts(self, counts):
        """Every count at most N = frames_per_k (`spadgen reconstruct` refuses more), read in blocks of about
        64 MB: a .npy file k by k, a Zarr store chunk by chunk (blocks of whole chunks, each decoded once; its
        chunks span every k); nothing to read where the dtype cannot exceed N."""
        n = self.frames_per_k
        if np.iinfo(counts.dtype).max <= n:
            return
        K, H, W = counts.shape
        size = counts.dtype.itemsize
        chunks = getattr(counts, "chunks", None)  # a zarr.Array's (a memory map has none)
        if isinstance(chunks, tuple) and len(chunks) == 3:
            ck, cy = max(1, min(K, int(chunks[0]))), max(1, int(chunks[1]))
            rows = max(cy, _CHECK_BLOCK_BYTES // max(1, ck * W * size) // cy * cy)
            blocks = ((k0, ck, y0, rows) for k0 in range(0, K, ck) for y0 in range(0, H, rows))
        else:
            step = max(1, _CHECK_BLOCK_BYTES // max(1, H * W * size))
            blocks = ((k0, step, 0, H) for k0 in range(0, K, step))
        for k0, nk, y0, ny in blocks:
            block = np.asarray(counts[k0:k0 + nk, y0:y0 + ny])
            if block.size and block.max() > n:
                k, y, x = (int(v) for v in np.argwhere(block > n)[0])
                raise ValueError(f"{self._require('counts.npy')}: the count at (k, y, x) = ({k0 + k}, {y0 + y}, {x}) is "
                                 f"{int(block[k, y, x])}, more than metadata.json's acquisition.frames_per_k = {n} (a count "
                                 "sums that many binary frames): the file is not this run's or was damaged; restore it, or "
                                 + self._remedy())

    @property
    def frames_packed(self):
        """(K, N, H, ceil(W / 8)) uint8 bit-packed binary frames, as stored; frames() unpacks them."""
        return self.array("frames.npy")

    @property
    def transient(self):
        """(H, W, T) float32 photons per laser pulse per time bin (over metadata.json's transient crop)."""
        return self.array("transient.npy")

    @property
    def transient_indirect(self):
        return self.array("transient_indirect.npy")

    @property
    def ground_truth(self):
        return self.exr("ground_truth.exr")

    @property
    def laser(self):
        return self.exr("laser.exr")

    @property
    def laser_standard_error(self):
        """(H, W) float32 photons per pulse: the Monte Carlo standard error of ``laser["photons_per_pulse"]``
        (laser.exr ``standard_error``; docs/render.md, "Accuracy"). None for a run saved before it; a
        FileNotFoundError, saying why, for a run that traced no laser (no laser.exr)."""
        laser = self.laser
        return laser["standard_error"] if "standard_error" in laser else None

    @property
    def ambient_standard_error(self):
        """(H, W) float32 photons per second: the Monte Carlo standard error of ``ambient["photons_per_second"]``
        (ambient.exr ``standard_error``; docs/render.md, "Accuracy"). None for a run saved before it."""
        ambient = self.ambient
        return ambient["standard_error"] if "standard_error" in ambient else None

    def expected_counts_error_bound(self, rows=slice(None), cols=slice(None)):
        """(K, H, W) float32: a first-order estimate of one standard error of the expected counts' Monte Carlo
        error, in counts (not a bound): N exp(-lambda) lambda times the larger of the pixel's relative standard
        errors of its laser return and of its ambient light (every detection counted as the noisier light;
        docs/render.md, "Accuracy"). The relative error is the pixel's whole return's: where the return has
        several parts, the gate positions that see only a weaker one (an object behind a plate) are off by more
        (about 1.4 times in rms on the multi-object scene), and in the dark, where the laser's part is below 1 % of
        the pixel's peak (the return's edges, the late light of inter-reflections), it is far too small, though the
        error there is a fraction of a count (docs/render.md, "Accuracy"). Zero where a pixel has neither. Needs detection_rate.npy and laser.exr's standard_error
        (ambient.exr's too where the run has it). The laser's error counts only where the counts see the laser:
        in a gate sweep, and in the intensity mode with acquisition.intensity.laser_on. rows, cols: the part of
        the image (slices), as indexing the whole result would give it."""
        rel = np.zeros((self.height, self.width), np.float64)[rows, cols]
        if self.mode == "gate_sweep" or self.acquisition.get("laser_on", False):
            se = self.laser_standard_error
            if se is None:
                raise KeyError(f"{self.path}/laser.exr has no standard_error channel (a run saved before it)")
            laser = np.asarray(self.laser["photons_per_pulse"][rows, cols], np.float64)
            rel = np.divide(np.asarray(se[rows, cols], np.float64), laser, out=np.zeros_like(laser), where=laser > 0)
        ase = self.ambient_standard_error
        if ase is not None:
            amb = np.asarray(self.ambient["photons_per_second"][rows, cols], np.float64)
            rel = np.maximum(rel, np.divide(np.asarray(ase[rows, cols], np.float64), amb, out=np.zeros_like(amb), where=amb > 0))
        lam = np.asarray(self.detection_rate[:, rows, cols], np.float64)
        return (self.frames_per_k * np.exp(-lam) * lam * rel[None, :, :]).astype(np.float32)

    @property
    def object_labels(self):
        return self.exr("labels.exr")

    @property
    def objects(self):
        """metadata.json's objects: one dict per glTF node with a mesh, ``id`` (the index the object
        channels hold), ``name`` (the node's), ``node`` (glTF index), ``meshes``, ``materials``."""
        return list(self._required("objects"))

    @property
    def ambient(self):
        return self.exr("ambient.exr")

    @property
    def sensor_maps(self):
        return self.exr("sensor_maps.exr")

    @property
    def intensity(self):
        return self.exr("intensity.exr")

    # ---- helpers ----------------------------------------------------------------------------------------

    def frames(self, k=slice(None), n=slice(None)):
        """Binary frames unpacked to 0 / 1 uint8: frames(k, n) is one (H, W) frame, frames(k) the (N, H, W)
        frames of gate position k, frames() all of them (K, N, H, W) (8 times the file's size in memory)."""
        packed = self.frames_packed
        for name, v, size, what in (("k", k, packed.shape[0], "gate positions"), ("n", n, packed.shape[1], "frames per position")):
            if isinstance(v, (str, bool, np.bool_)):
                raise TypeError(f"{self.path}: frames({name}={v!r}); expected an int, a slice or indices")
            # a single index is checked; slices, lists and arrays of indices go to NumPy as they are
            if (i := _position(v)) is not None and not -size <= i < size:
                raise IndexError(f"{self.path}: frames({name}={i}) is past the {size} {what} (0 to {size - 1})")
        return unpack_frames(packed[k, n], self.width)

    def gate_profile(self, x, y, expected=False, sensor_coordinates=False):
        """The gate profile of pixel (x, y): counts (or, with expected=True, expected counts) against the gate
        positions in ns. x, y are image coordinates, or sensor coordinates (as metadata.json's
        preview_profile_pixels) with sensor_coordinates=True."""
        for name, v in (("x", x), ("y", y)):  # (2.7 reached NumPy's indexing: "only integers, slices ...")
            if isinstance(v, bool) or not isinstance(v, numbers.Integral):
                raise TypeError(f"gate_profile: {name} = {v!r}; expected a whole pixel index (an int)")
        if sensor_coordinates:
            sx, sy = x, y
            x, y = x - self.crop[0], y - self.crop[1]
            if not (0 <= x < self.width and 0 <= y < self.height):
                c = self.crop
                raise IndexError(f"{self.path}: sensor pixel (x {sx}, y {sy}) lies outside the run's crop, x {c[0]} to "
                                 f"{c[0] + c[2] - 1} and y {c[1]} to {c[1] + c[3] - 1} (sensor_coordinates=True)")
        if not (0 <= x < self.width and 0 <= y < self.height):
            raise IndexError(f"{self.path}: pixel (x {x}, y {y}) lies outside the {self.width} x {self.height} image")
        if expected and not self.has("expected_counts.npy") and self.has("detection_rate.npy"):
            # as expected_counts computes it, for this pixel's rates only (not the whole stack in float64)
            lam = np.asarray(self.detection_rate[:, y, x], np.float64)
            return Profile(self.gate_positions_ns, (self.frames_per_k * -np.expm1(-lam)).astype(np.float32), int(x), int(y))
        stack = self.expected_counts if expected else self.counts
        return Profile(self.gate_positions_ns, np.asarray(stack[:, y, x]), int(x), int(y))

    def depth(self, kind="range"):
        """(H, W) float32 ground-truth depth in metres: "range" (along the pixel's ray, what time of flight
        measures) or "z" (along the optical axis); +inf where the ray hits nothing."""
        if kind not in ("range", "z"):
            raise ValueError(f"kind must be 'range' or 'z', got {kind!r}")
        return self.ground_truth[kind]

    def hit(self):
        """(H, W) bool: the pixel's ray hits a surface."""
        return np.isfinite(self.ground_truth["range"])

    def layers(self):
        """Every surface along each pixel's ray (Layers: count, range, transmittance)."""
        gt = self.ground_truth
        n = int(self._meta("ground_truth_layers"))
        shape = (n, self.height, self.width)
        rng = np.stack([gt[f"layer{i}.range"] for i in range(n)]) if n else np.empty(shape, np.float32)
        tr = np.stack([gt[f"layer{i}.transmittance"] for i in range(n)]) if n else np.empty(shape, np.float32)
        return Layers(gt["layer_count"].astype(np.int32), rng, tr)

    def object_slots(self):
        """The objects along each pixel's ray, what each returns and whether it is detectable (ObjectSlots)."""
        gt = self.ground_truth
        n = int(self._meta("ground_truth_objects"))
        shape = (n, self.height, self.width)

        def slots(image, what, dtype=np.float32):
            return np.stack([image[f"object{j}.{what}"] for j in range(n)]).astype(dtype) if n else np.empty(shape, dtype)

        labels = {}
        if self.has("labels.exr"):
            lab = self.object_labels
            labels = {"edge_counts": slots(lab, "edge_counts"), "edge_snr": slots(lab, "edge_snr"),
                      "detectable": slots(lab, "detectable", bool)}
        traced = "direct_other_laser" in gt  # else the run traced no laser
        return ObjectSlots(gt["object_id"].astype(np.int32), gt["object_count"].astype(np.int32), slots(gt, "id", np.int32),
                           slots(gt, "range"), slots(gt, "transmittance"), slots(gt, "laser") if traced else None,
                           gt["direct_other_laser"] if traced else None, gt["indirect_laser"] if traced else None,
                           path=slots(gt, "path"), **labels)

    def detections(self, detector="edges", noise_free=False, path=None):
        """The returns ``spadgen reconstruct RUN --detector DETECTOR`` wrote into the run folder (Detections);
        noise_free: those of ``--noise-free`` (from the noise-free rates lambda, detection_rate),
        detections_<detector>_noise_free.exr. path: a file reconstruct wrote elsewhere (``-o FILE``) from this
        run, whatever its detector (Detections.detector says which)."""
        suffix = "_noise_free" if noise_free else ""
        given = path is not None
        if self.mode != "gate_sweep":
            raise ValueError(f"{self.path} is a 2D run ({self.mode}): no gate profiles to detect returns in; "
                             f"spadgen reconstruct {self.path}{' --noise-free' if noise_free else ''} writes its HDR inversion, "
                             f"which run.hdr({'noise_free=True' if noise_free else ''}) reads")
        path = os.fspath(path) if given else os.path.join(self.path, f"detections_{detector}{suffix}.exr")
        if not os.path.exists(path):  # (anything else in its place: ExrFile names what it is)
            flag = " --noise-free" if noise_free else ""
            raise FileNotFoundError(f"{path}: {_missing(path)}; write it with spadgen reconstruct {self.path} --detector "
                                    f"{detector}{flag}" + (f" -o {path}" if given else ""))
        f = ExrFile(path)
        self._check_image(f)
        m = 0
        while f"det{m}.range" in f:
            m += 1

        def slots(what):
            return np.stack([f[f"det{i}.{what}"] for i in range(m)]).astype(np.float32)

        attrs = f.attributes
        try:  # (unreadable: as if absent, as the program takes it)
            made = json.loads(attrs.get("spadgen_reconstruct", "{}"))
        except ValueError:
            made = {}
        made_nf = made.get("noise_free") is True if isinstance(made, dict) else False  # (as the program: not true, false)
        if not given and isinstance(made, dict) and "detector" in made and (made["detector"], made_nf) != (detector, noise_free):
            raise ValueError(f"{path}: written by reconstruct's {made['detector']} detector"
                             f"{' on the noise-free rates' if made_nf else ''}, not the {detector} detector"
                             f"{' on the noise-free rates' if noise_free else ''} its name stands for (reconstruct -o named "
                             "it so); write it again with spadgen reconstruct")
        source = self._check_source(f, "the detections are")
        return Detections(np.asarray(f["count"]).astype(np.int32), slots("range"), slots("gate"), slots("amplitude"),
                          slots("score"), made, source if isinstance(source, dict) else {})

    def hdr(self, noise_free=False, path=None):
        """The HDR inversion of a 2D run that ``spadgen reconstruct RUN`` (``--noise-free``) wrote into its folder,
        hdr.exr (hdr_noise_free.exr): channels photons, photons_se, saturated (docs/detection.md). path: one
        reconstruct wrote elsewhere (``-o FILE``) from this run."""
        given = path is not None
        path = os.fspath(path) if given else os.path.join(self.path, "hdr_noise_free.exr" if noise_free else "hdr.exr")
        if not os.path.exists(path):
            if self.mode == "gate_sweep":
                raise ValueError(f"{self.path} is a gate sweep: reconstruct writes its detections (run.detections()), "
                                 "not an HDR inversion, which is for 2D runs")
            flag = " --noise-free" if noise_free else ""
            raise FileNotFoundError(f"{path}: {_missing(path)}; write it with spadgen reconstruct {self.path}{flag}"
                                    + (f" -o {path}" if given else ""))
        image = ExrFile(path)
        self._check_image(image)
        self._check_source(image, "the HDR inversion is")
        return image

    def _check_source(self, image, what):
        """A file reconstruct derived from a run (its header's spadgen_source, a JSON object) is of this run, as
        spadgen evaluate checks it: the same scene files (scene_hash_fnv1a64), crop of the sensor and settings
        (settings_hash: --set values, a dataset sample's parameters; another seed's or realisation's file is
        of this run). What either side does not record is not compared. The source as a dict ({} when absent
        or unreadable, as the program takes it)."""
        try:
            source = json.loads(image.attributes.get("spadgen_source", "{}"))
        except ValueError:
            source = {}
        if not isinstance(source, dict):
            return {}
        made_from = source.get("run", "?")
        ours = {"scene_hash_fnv1a64": ("another scene (scene file and glTF hash)", self.metadata.get("scene_hash_fnv1a64")),
                "crop_in_sensor": ("another crop of the sensor",
                                   list(self.crop) if "crop_in_sensor" in self.metadata.get("image", {}) else None),
                "settings_hash": ("other settings (a --set value, a dataset sample's parameters or the dataset's set)",
                                  self.metadata.get("settings_hash_fnv1a64"))}
        for key, (name, mine) in ours.items():
            theirs = source.get(key)
            if theirs is not None and mine is not None and theirs != mine:
                raise ValueError(f"{image.path}: {what} of {name} than {self.path}'s (made from {made_from}: "
                                 f"{json.dumps(theirs)}, this run: {json.dumps(mine)}); write them again with "
                                 f"spadgen reconstruct {self.path}")
        return source

    def layer_count(self):
        """(H, W) int32: the number of surfaces along each pixel's ray."""
        return self.ground_truth["layer_count"].astype(np.int32)

    def labels(self):
        """(mesh_id, material_id), each (H, W) int32, of the first surface each ray hits; -1 for none."""
        gt = self.ground_truth
        return gt["mesh_id"].astype(np.int32), gt["material_id"].astype(np.int32)

    # ---- camera -----------------------------------------------------------------------------------------

    def _camera_matrix(self, key):
        """metadata.json's camera.key as a float64 array (_check_metadata checked its shape and numbers)."""
        if "camera" not in self.metadata:
            raise KeyError(f"{self.path}: metadata.json has no camera section (written by a spadgen before "
                           "version 0.1.0 had it): run the scene again")
        return np.asarray(self._required("camera", key), np.float64)

    @property
    def intrinsics(self):
        """(3, 3) float64 intrinsic matrix of the images (OpenCV convention, crop included; spadgen.camera)."""
        return self._camera_matrix("intrinsics")

    @property
    def camera_to_world(self):
        """(4, 4) float64 pose: camera frame (x right, y down, z forward) to the glTF world frame."""
        return self._camera_matrix("camera_to_world")

    @property
    def world_to_camera(self):
        return _camera.invert_pose(self.camera_to_world)

    def points(self, frame="camera", depth=None, kind="range"):
        """(H, W, 3) float64 points of a depth image (the ground truth's by default) in the "camera" or
        "world" frame; NaN where the depth is not finite."""
        if depth is None:
            depth = self.depth(kind)
        if frame not in ("camera", "world"):
            raise ValueError(f"frame must be 'camera' or 'world', got {frame!r}")
        return _camera.depth_to_points(depth, self.intrinsics, kind,
                                       self.camera_to_world if frame == "world" else None)

    def point_cloud(self, frame="camera", depth=None, kind="range"):
        """(P, 3) float64: points() of the pixels with a finite depth, in row-major pixel order."""
        p = self.points(frame, depth, kind).reshape(-1, 3)
        return p[np.isfinite(p).all(axis=1)]


def _position(value):
    """An item's position as an int (anything with __index__: NumPy's and torch's 0-d integers, as torch's Subset
    passes them), or None for what is none (a bool, a float, a text)."""
    if isinstance(value, (bool, np.bool_)):
        return None
    try:
        return operator.index(value)
    except TypeError:
        return None


def _missing(path):
    """What is at a path that does not exist: nothing, or a symbolic link to nothing (named with its target)."""
    if os.path.islink(path):
        return f"a symbolic link to {os.readlink(path)}, which does not exist"
    return "no such file"


def open_run(path):
    """Opens a run folder (reads metadata.json only)."""
    if not isinstance(path, (str, bytes, os.PathLike)):
        raise TypeError(f"open_run({path!r}): expected a run folder's path (str or os.PathLike)")
    return Run(path)
