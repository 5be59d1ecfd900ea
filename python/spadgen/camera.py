"""Pinhole geometry of spadgen's images: pixel rays, depth to points, projection.

Conventions (those of OpenCV and metadata.json's ``camera`` section): the camera frame has x to the right,
y down and z forward (the viewing direction); pixel (u, v) of an image is centred at the integer point
(u, v), with (0, 0) the image's top-left pixel. ``K`` is the 3 x 3 intrinsic matrix [[f, 0, cx], [0, f, cy],
[0, 0, 1]] in pixels, ``camera_to_world`` a 4 x 4 rigid transform into the glTF scene's world frame.

Depth comes in two kinds, as in ground_truth.exr: ``range`` is the distance from the camera centre along the
pixel's ray (what time of flight measures), ``z`` the distance along the optical axis.
"""
from __future__ import annotations

import numpy as np

__all__ = ["pixel_rays", "depth_to_points", "project", "transform", "invert_pose"]


def pixel_rays(K, width, height):
    """Unit directions (H, W, 3) float64 in the camera frame through the centre of every pixel."""
    K = np.asarray(K, np.float64)
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    d = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], axis=-1)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def depth_to_points(depth, K, kind="range", camera_to_world=None):
    """Points (H, W, 3) float64 of a depth image (H, W): in the camera frame, or in the world frame when
    ``camera_to_world`` is given. ``kind`` says what the depth is: "range" (along the ray) or "z" (along the
    optical axis). Pixels whose depth is not finite (+inf: the ray hit nothing) give NaN points."""
    depth = np.asarray(depth, np.float64)
    if depth.ndim != 2:
        raise ValueError(f"depth must be an (H, W) image, got shape {depth.shape}")
    h, w = depth.shape
    rays = pixel_rays(K, w, h)
    if kind == "range":
        scale = depth
    elif kind == "z":
        scale = depth / rays[..., 2]
    else:
        raise ValueError(f"kind must be 'range' or 'z', got {kind!r}")
    scale = np.where(np.isfinite(scale), scale, np.nan)
    pts = rays * scale[..., None]
    return pts if camera_to_world is None else transform(pts, camera_to_world)


def transform(points, M):
    """Applies a 4 x 4 rigid transform to points (..., 3)."""
    M = np.asarray(M, np.float64)
    p = np.asarray(points, np.float64)
    return p @ M[:3, :3].T + M[:3, 3]


def invert_pose(M):
    """The inverse of a 4 x 4 rigid transform (world_to_camera from camera_to_world)."""
    M = np.asarray(M, np.float64)
    inv = np.eye(4)
    inv[:3, :3] = M[:3, :3].T
    inv[:3, 3] = -M[:3, :3].T @ M[:3, 3]
    return inv


def project(points, K, world_to_camera=None):
    """Pixel coordinates (..., 2) [u, v] of points (..., 3) in the camera frame (or in the world frame, with
    ``world_to_camera``). Points at or behind the camera (z <= 0) give NaN."""
    p = np.asarray(points, np.float64)
    if world_to_camera is not None:
        p = transform(p, world_to_camera)
    K = np.asarray(K, np.float64)
    z = np.where(p[..., 2] > 0, p[..., 2], np.nan)
    return np.stack([K[0, 0] * p[..., 0] / z + K[0, 2], K[1, 1] * p[..., 1] / z + K[1, 2]], axis=-1)
