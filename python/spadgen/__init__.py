"""Python access to spadgen's outputs: runs (metadata, stacks, EXR images, frames, camera), plots, and a
PyTorch Dataset. Pure Python on NumPy; matplotlib for spadgen.plot, PyTorch for spadgen.torchdata.

    import spadgen
    run = spadgen.open_run("out/multi_object")
    depth = run.depth()                      # (H, W) float32 metres, +inf where nothing was hit
    xyz = run.points(frame="world")          # (H, W, 3) ground-truth points
    profile = run.gate_profile(300, 120)     # counts against gate position (ns)

Reference: docs/python.md.
"""
from ._version import __version__
from .camera import depth_to_points, invert_pose, pixel_rays, project, transform
from .exr import ExrError, ExrFile, read_exr
from .run import Layers, Profile, Run, TimeAxis, open_run, unpack_frames

__all__ = ["__version__", "open_run", "Run", "TimeAxis", "Profile", "Layers", "unpack_frames", "ExrFile",
           "ExrError", "read_exr", "depth_to_points", "pixel_rays", "project", "transform", "invert_pose",
           "RunDataset"]


def __getattr__(name):
    # spadgen.RunDataset imports PyTorch only when asked for.
    if name == "RunDataset":
        from .torchdata import RunDataset
        return RunDataset
    raise AttributeError(f"module 'spadgen' has no attribute {name!r}")
