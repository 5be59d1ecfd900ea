"""Scoring detections from Python: `spadgen evaluate` run on a run folder or a dataset folder, its metrics.json
returned as a dict. The program is the one scorer (matching, unfolding, labels: docs/detection.md); this module
passes it the detections, as files or as arrays."""
import json
import os
import pathlib
import shutil
import subprocess
import tempfile

import numpy as np

__all__ = ["evaluate", "EvaluateError", "spadgen_program"]


class EvaluateError(RuntimeError):
    """`spadgen evaluate` refused the input or failed: its message, exit status and command."""

    def __init__(self, message, returncode, command):
        super().__init__(message)
        self.returncode = returncode
        self.command = command


def spadgen_program(program=None):
    """The spadgen program to run: `program` when given, else $SPADGEN_BIN, else `spadgen` on PATH, else the
    README's build/app/spadgen beside this package in a source checkout. FileNotFoundError saying how to
    point at it when none exists."""
    if program is not None:
        if not (os.path.isfile(program) and os.access(program, os.X_OK)):
            raise FileNotFoundError(f"{os.fspath(program)}: no such executable file (program=: the spadgen program; "
                                    "without it: $SPADGEN_BIN, spadgen on PATH or the build folder)")
        return os.fspath(program)
    tried = []
    for candidate in (os.environ.get("SPADGEN_BIN"), shutil.which("spadgen"),
                      pathlib.Path(__file__).resolve().parents[2] / "build" / "app" / "spadgen"):
        if candidate is None:
            continue
        candidate = os.fspath(candidate)
        tried.append(candidate)
        if os.path.isfile(candidate) and os.access(candidate, os.X_OK):
            return candidate
    raise FileNotFoundError("no spadgen program found (tried " + (", ".join(tried) or "nothing") + "): pass "
                            "program=PATH, set SPADGEN_BIN, or put spadgen on PATH")


def _ranges_array(a, what):
    a = np.asarray(a)
    if a.ndim != 3 or a.dtype.kind != "f":
        raise ValueError(f"{what}: expected a float array (H, W, M) of ranges in metres (NaN: none), got "
                         f"{a.dtype} of shape {a.shape}")
    return np.ascontiguousarray(a, dtype=np.float32 if a.dtype.itemsize <= 4 else np.float64)


def _done_folder_names(dataset):
    from .dataset import open_dataset
    names = []
    for s in open_dataset(dataset).select(status="done"):
        names.append(os.path.basename(s.folder))
        names.extend(os.path.basename(f) for f in s.repeat_folders)
    return names


def evaluate(target, detections=None, *, detector=None, out=None, tolerance_m=None, min_score=None, region=None,
             noise_free=False, threads=None, program=None):
    """Scores detections against the object labels of a run folder or of every done sample of a dataset folder
    with `spadgen evaluate` (docs/detection.md), and returns its metrics.json as a dict.

    detections:
      - None: each run's detections_<detector>.exr, or the detector run in memory where it is absent;
      - a path: a detections file (.exr or .npy) of the run; for a dataset, a name inside each sample folder
        or a path with {sample}, replaced by each sample folder's name ("preds/{sample}.npy");
      - an array (H, W, M) of ranges in metres, NaN where there is none (a run);
      - a mapping {sample folder name: array} (a dataset: "000042", "000042_r01" for a realisation), one per
        done sample folder.
    Arrays are written as .npy into a temporary folder, removed afterwards (metrics.json's
    detections_source names the file the program read).

    The other arguments are the command's options (--detector, -o, --tolerance-m, --min-score,
    --region (x, y, w, h), --noise-free, --threads); out defaults to TARGET/evaluation, which is replaced.
    program: the spadgen program (spadgen_program()). EvaluateError with the program's message when it
    refuses the input.
    """
    target = os.fspath(target)
    exe = spadgen_program(program)
    with tempfile.TemporaryDirectory(prefix="spadgen_evaluate_") as tmp:
        if detections is None or isinstance(detections, (str, os.PathLike)):
            given = None if detections is None else os.fspath(detections)
        elif hasattr(detections, "keys"):
            if not os.path.isfile(os.path.join(target, "dataset.json")):
                raise ValueError(f"{target}: not a dataset folder (dataset.json): a mapping of detections names the "
                                 "samples of a dataset; give a run's detections as one array")
            done = set(_done_folder_names(target))
            unknown = sorted(str(k) for k in detections.keys() if str(k) not in done)
            if unknown:
                raise ValueError(f"detections for {len(unknown)} folders that are no done sample folder of {target}, "
                                 f"first {unknown[0]!r} (done: {', '.join(sorted(done)[:4])}{', ...' if len(done) > 4 else ''})")
            for name, a in detections.items():
                np.save(os.path.join(tmp, f"{name}.npy"), _ranges_array(a, f"detections[{name!r}]"))
            given = os.path.join(tmp, "{sample}.npy")
        else:
            given = os.path.join(tmp, "detections.npy")
            np.save(given, _ranges_array(detections, "detections"))
        out_dir = os.fspath(out) if out is not None else os.path.join(target, "evaluation")
        cmd = [exe, "evaluate", target, "-q", "-o", out_dir]
        if given is not None:
            cmd += ["--detections", given]
        if detector is not None:
            cmd += ["--detector", str(detector)]
        if tolerance_m is not None:
            cmd += ["--tolerance-m", repr(float(tolerance_m))]
        if min_score is not None:
            cmd += ["--min-score", repr(float(min_score))]
        if region is not None:
            cmd += ["--region", ",".join(str(int(v)) for v in region)]
        if noise_free:
            cmd += ["--noise-free"]
        if threads is not None:
            cmd += ["--threads", str(int(threads))]
        p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        if p.returncode != 0:
            message = p.stderr.strip() or p.stdout.strip() or f"exit status {p.returncode}"
            raise EvaluateError(message, p.returncode, cmd)
        with open(os.path.join(out_dir, "metrics.json"), encoding="utf-8") as f:
            return json.load(f)
