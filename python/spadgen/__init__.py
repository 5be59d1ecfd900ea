"""Python access to spadgen's outputs: runs (metadata, stacks, EXR images, frames, camera), datasets (their
index, filtering, samples), plots, and PyTorch Datasets. Pure Python on NumPy; matplotlib for spadgen.plot,
PyTorch for spadgen.torchdata.

    import spadgen
    run = spadgen.open_run("out/multi_object")
    depth = run.depth()                      # (H, W) float32 metres, +inf where nothing was hit
    xyz = run.points(frame="world")          # (H, W, 3) ground-truth points
    profile = run.gate_profile(300, 120)     # counts against gate position (ns)
    ds = spadgen.open_dataset("out/plates")  # a `spadgen dataset run` folder
    for sample in ds.select(status="done"):
        sample.parameters, sample.run.counts
    spadgen.evaluate(run, ranges)            # your (H, W, M) ranges scored (spadgen evaluate); a dataset takes
                                             # {folder name: ranges} for every done sample folder

Reference: docs/python.md.
"""
from ._version import __version__
from .camera import depth_to_points, invert_pose, pixel_rays, project, transform
from .dataset import Dataset, Sample, SampleNotDoneError, open_dataset
from .evaluate import EvaluateError, evaluate
from .exr import ExrError, ExrFile, read_exr
from .run import Detections, Layers, ObjectSlots, Profile, Run, RunChangedError, TimeAxis, open_run, unpack_frames

__all__ = ["__version__", "open_run", "Run", "RunChangedError", "TimeAxis", "Profile", "Layers", "ObjectSlots", "Detections", "unpack_frames", "ExrFile",
           "ExrError", "read_exr", "depth_to_points", "pixel_rays", "project", "transform", "invert_pose",
           "open_dataset", "Dataset", "Sample", "SampleNotDoneError", "evaluate", "EvaluateError", "RunDataset", "DatasetSamples"]


def __getattr__(name):
    # spadgen.RunDataset and spadgen.DatasetSamples import PyTorch only when asked for.
    if name in ("RunDataset", "DatasetSamples"):
        from . import torchdata
        return getattr(torchdata, name)
    raise AttributeError(f"module 'spadgen' has no attribute {name!r}")
