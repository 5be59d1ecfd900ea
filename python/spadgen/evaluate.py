"""Scoring detections from Python: `spadgen evaluate` run on a run folder or a dataset folder, its metrics.json
returned as a dict. The program is the one scorer (matching, unfolding, labels: docs/detection.md); this module
passes it the detections, as files or as arrays."""
import json
import operator
import os
import pathlib
import re
import shutil
import subprocess
import tempfile
import warnings

import numpy as np

__all__ = ["evaluate", "EvaluateError", "spadgen_program"]


class EvaluateError(RuntimeError):
    """`spadgen evaluate` refused the input or failed: its message, exit status and command."""

    def __init__(self, message, returncode, command):
        super().__init__(message)
        self.returncode = returncode
        self.command = command


def _executable(path):
    return os.path.isfile(path) and os.access(path, os.X_OK)


def spadgen_program(program=None):
    """The spadgen program to run: `program` when given, else $SPADGEN_BIN, else the README's build/app/spadgen
    of the source checkout this package sits in, else `spadgen` on PATH. A program named (by the argument or
    $SPADGEN_BIN) must be an executable file; FileNotFoundError saying how to point at one when none is found.
    A program of another version than the package's is used with a warning (an older one may lack what the
    package passes it)."""
    for given, how in ((program, "program="), (os.environ.get("SPADGEN_BIN"), "$SPADGEN_BIN")):
        if given is not None and given != "":
            given = os.fspath(given)
            if os.sep not in given:  # a bare name, as a shell finds it: on PATH
                given = shutil.which(given) or given
            if not _executable(given):
                raise FileNotFoundError(f"{os.fspath(given)} ({how}): no such executable file; expected the spadgen program")
            return _checked_version(os.fspath(given))
    checkout = pathlib.Path(__file__).resolve().parents[2] / "build" / "app" / "spadgen"
    for candidate in (str(checkout), shutil.which("spadgen")):
        if candidate is not None and _executable(candidate):
            return _checked_version(candidate)
    raise FileNotFoundError(f"no spadgen program found (tried {checkout} and spadgen on PATH): pass program=PATH, "
                            "set SPADGEN_BIN, or put spadgen on PATH")


_versions = {}


def _checked_version(program):
    if program not in _versions:
        try:
            out = subprocess.run([program, "--version"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                                 timeout=60).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            out = ""
        _versions[program] = out
        from ._version import __version__
        if out.split()[-1:] != [__version__]:
            warnings.warn(f"{program} says its version is {out or 'nothing'!r}, the package is {__version__}: "
                          "results may differ from the docs", stacklevel=3)
    return program


def _ranges_array(a, what, folder):
    a = np.asarray(a)
    if a.ndim != 3 or a.dtype.kind != "f":
        raise ValueError(f"{what}: expected a float array (H, W, M) of ranges in metres (NaN: none), got "
                         f"{a.dtype} of shape {a.shape}")
    # the run's image, checked here: the program's message would name a temporary file already gone
    from .run import open_run
    run = open_run(folder)
    if a.shape[:2] != (run.height, run.width):
        hint = " (an (M, H, W) array, as Run.detections().range and torch's object_range are: np.moveaxis(a, 0, -1))" \
            if a.shape[1:] == (run.height, run.width) else ""
        raise ValueError(f"{what}: shape {a.shape}, expected ({run.height}, {run.width}, M): the image of {folder}{hint}")
    a = np.ascontiguousarray(a, dtype=np.float32 if a.dtype.itemsize <= 4 else np.float64)
    # the values too (the program's message named the temporary file, already gone): NaN is none, others >= 0
    bad = np.isinf(a) | (a < 0)
    if bad.any():
        y, x, m = (int(v) for v in np.argwhere(bad)[0])
        raise ValueError(f"{what}: [{y}, {x}, {m}] (y, x, slot) is {float(a[y, x, m])!r}, and {int(bad.sum())} values in all "
                         "are infinite or negative; expected ranges in metres >= 0, NaN where there is none")
    return a


# The command's flags as this function's arguments, for its messages (EvaluateError)
_ARGUMENTS = {"--detections": "detections=", "--detector": "detector=", "--tolerance-m": "tolerance_m=",
              "--min-score": "min_score=", "--region": "region=", "--noise-free": "noise_free=True", "--threads": "threads="}


def _done_folder_names(dataset, selection=None):
    """The done sample folders' names (realisations too; of the selected dataset indices), and those of them
    that are 2D intensity runs."""
    from .dataset import open_dataset
    names, intensity = [], set()
    for s in open_dataset(dataset).select(status="done"):
        if selection is not None and s.index not in selection:
            continue
        folders = [os.path.basename(f) for f in [s.folder] + s.repeat_folders]
        names.extend(folders)
        if s.run.mode == "intensity":  # (without detections given, evaluate leaves them out, as its detector does)
            intensity.update(folders)
    return names, intensity


def evaluate(target, detections=None, *, detector=None, out=None, tolerance_m=None, min_score=None, region=None,
             noise_free=False, threads=None, program=None, tmp_dir=None):
    """Scores detections against the object labels of a run folder or of every done sample of a dataset folder
    with `spadgen evaluate` (docs/detection.md), and returns its metrics.json as a dict. target: a folder, or a
    Dataset selection (spadgen.open_dataset(...).select(...), a slice): its samples only (--samples), e.g. a
    validation split, or a Run (its folder).

    detections:
      - None: each run's detections_<detector>.exr, or the detector run in memory where it is absent;
      - a path: a detections file (.exr or .npy) of the run; for a dataset, a name inside each sample folder
        or a path with {sample}, replaced by each sample folder's name ("preds/{sample}.npy");
      - an array (H, W, M) of ranges in metres, NaN where there is none (a run);
      - a mapping {sample folder name: array} (a dataset: "000042", "000042_r01" for a realisation), one per
        done sample folder of the selection (a 2D sample's may be left out: it is not scored then).
    Arrays are written as .npy into a temporary folder in tmp_dir (default: Python's, often a tmpfs in
    memory: a whole dataset's detections are written at once), removed afterwards (metrics.json's
    detections_source names the file the program read).

    The other arguments are the command's options (--detector, -o, --tolerance-m, --min-score,
    --region (x, y, w, h), --noise-free, --threads); out defaults to TARGET/evaluation, which is replaced.
    program: the spadgen program (spadgen_program()). EvaluateError with the program's message when it
    refuses the input.
    """
    from .dataset import Dataset
    from .run import Run
    selection = None
    if isinstance(target, Run):  # (as RunDataset takes one): its folder
        target = target.path
    elif isinstance(target, Dataset):  # a dataset, or a selection of one (Dataset.select, slicing): its samples only
        if len(target) == 0:
            raise ValueError(f"{target.path}: the selection holds no samples; expected some to score")
        if len(target) < len(target._all):  # (the whole dataset: no --samples, as for its folder)
            selection = {int(i) for i in target.indices}
        target = target.path
    target = os.fspath(target)
    # What the program refuses of these, said in the arguments' names (its message named its flags, and a
    # temporary file already gone)
    if detections is not None and (detector is not None or noise_free):
        raise ValueError("detector= and noise_free= choose the detector evaluate runs, or whose file in the run it reads, "
                         "when detections is None; with detections given, leave them out")
    arrays = detections is not None and not isinstance(detections, (str, os.PathLike))
    if arrays and min_score is not None:
        raise ValueError("min_score: arrays of ranges hold no scores (it keeps the detections of a score at least "
                         "this, as spadgen reconstruct's .exr files hold them); leave min_score out")
    exe = spadgen_program(program)
    dataset = os.path.isfile(os.path.join(target, "dataset.json"))
    with tempfile.TemporaryDirectory(prefix="spadgen_evaluate_", dir=tmp_dir) as tmp:
        if "{sample}" in tmp:  # (the program would take it for the placeholder)
            raise ValueError(f"{tmp}: the temporary folder's path holds {{sample}}, which --detections replaces; "
                             "give another tmp_dir")
        if detections is None or isinstance(detections, (str, os.PathLike)):
            given = None if detections is None else os.fspath(detections)
        elif hasattr(detections, "keys"):
            if not dataset:
                raise ValueError(f"{target}: not a dataset folder (dataset.json): a mapping of detections names the "
                                 "samples of a dataset; give a run's detections as one array")
            names, intensity = _done_folder_names(target, selection)
            done = set(names)
            missing = sorted(done - intensity - {str(k) for k in detections.keys()})
            if missing:
                raise ValueError(f"no detections for {len(missing)} of the {len(done)} done sample folders of {target}, "
                                 f"first {missing[0]!r}: the mapping needs one array per done sample folder (realisations too)")
            unknown = sorted(str(k) for k in detections.keys() if str(k) not in done)
            if unknown and selection is not None:  # (a done sample outside the selection was said to be none)
                every_done = set(_done_folder_names(target, None)[0])  # (once: it opens every done sample's run)
                outside = [u for u in unknown if u in every_done]
                if outside:
                    chosen = sorted(selection)
                    raise ValueError(f"detections for {len(outside)} done sample folders of {target} outside the selection "
                                     f"(samples {chosen[:8]}{' ...' if len(chosen) > 8 else ''}), first {outside[0]!r}: "
                                     "give detections of the selection's samples only, or evaluate the whole dataset")
            if unknown:
                raise ValueError(f"detections for {len(unknown)} folders that are no done sample folder of {target}, "
                                 f"first {unknown[0]!r} (done: {', '.join(sorted(done)[:4])}{', ...' if len(done) > 4 else ''})")
            for name, a in detections.items():
                np.save(os.path.join(tmp, f"{name}.npy"),
                        _ranges_array(a, f"detections[{name!r}]", os.path.join(target, "samples", str(name))))
            given = os.path.join(tmp, "{sample}.npy")
        else:
            if dataset:
                raise ValueError(f"{target} is a dataset folder: give its detections as a mapping {{sample folder name: "
                                 "array}, or files (a name inside each sample folder, or a path with {sample})")
            given = os.path.join(tmp, "detections.npy")
            np.save(given, _ranges_array(detections, "detections", target))
        out_dir = os.fspath(out) if out is not None else os.path.join(target, "evaluation")
        cmd = [exe, "evaluate", "-q", "-o", out_dir]
        if given is not None:
            cmd += ["--detections", given]
        if detector is not None:
            cmd += ["--detector", str(detector)]
        if tolerance_m is not None:
            cmd += ["--tolerance-m", repr(float(tolerance_m))]
        if min_score is not None:
            cmd += ["--min-score", repr(float(min_score))]
        if region is not None:  # (whole pixels: 0.9 was taken as 0)
            cmd += ["--region", ",".join(str(operator.index(v)) for v in region)]
        if noise_free:
            cmd += ["--noise-free"]
        if threads is not None:
            cmd += ["--threads", str(operator.index(threads))]
        if selection is not None:  # (a file: a long list exceeds what one argument may hold)
            with open(os.path.join(tmp, "samples.txt"), "w") as f:
                f.write("\n".join(str(i) for i in sorted(selection)) + "\n")
            cmd += ["--samples", "@" + os.path.join(tmp, "samples.txt")]
        cmd += ["--", target]  # (a target named -x is no option)
        p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        if p.returncode != 0:
            message = p.stderr.strip() or p.stdout.strip() or f"exit status {p.returncode}"
            named = [f"{flag} is {arg}" for flag, arg in _ARGUMENTS.items() if re.search(re.escape(flag) + r"\b", message)]
            if named:
                message += f" [spadgen.evaluate: {', '.join(named)}]"
            raise EvaluateError(message, p.returncode, cmd)
        try:
            with open(os.path.join(out_dir, "metrics.json"), encoding="utf-8") as f:
                return json.load(f)
        except (OSError, ValueError) as e:
            raise EvaluateError(f"{out_dir}/metrics.json: the program ended without error but the file does not read "
                                f"({e})", p.returncode, cmd) from None
