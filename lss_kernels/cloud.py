"""Point clouds of a solve: every pixel seen by both cameras as a coloured 3-D point with its
layer, written as binary little-endian PLY (through ``plyfile``).

The points are those of :meth:`lss_kernels.calib.Calibration.points` (the left camera's
frame, x right, y down, z forward, in the baseline's unit).  An occluded pixel (seen by the
left camera only, Sec. 2) has no match and gives no point, so no point of the cloud hangs
between the object and its background at the occlusion strip: each pixel lies on its own
layer's surface.  The layer index is an input (0 background, 1 the object for the two-layer
model).

PLY vertex properties: ``x y z`` (float32), ``red green blue`` (uint8), ``layer`` (uint8)
and, when the solve's confidence is given, ``confidence`` (float32 in [0, 1],
:mod:`lss_kernels.confidence`): a pixel that holds no distinct match of its own takes its
layer's smoothed surface, and most of the points that lie off both true surfaces are such
pixels, so keeping the confident points (``min_confidence`` of :func:`select`, or a filter
on the property) trades points for accuracy.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["WHICH", "cloud", "read_ply", "select", "write_ply"]

#: The selections of :func:`select`.
WHICH = ("all", "object", "background")


def select(which, foreground, occlusion, confidence=None, min_confidence=0.0) -> np.ndarray:
    """The pixels (bool ``(H, W)``) of a cloud: ``"all"`` those seen by both cameras (not
    occluded), ``"object"`` those of the foreground, ``"background"`` the rest; with
    ``min_confidence`` > 0, only those whose ``confidence`` is at least that."""
    visible = ~np.asarray(occlusion, bool)
    fg = np.asarray(foreground, bool)
    if isinstance(min_confidence, bool) or not isinstance(min_confidence, (int, float)) \
            or not 0.0 <= min_confidence <= 1.0:
        raise ValueError(f"min_confidence: expected a number in [0, 1], got {min_confidence!r}")
    if min_confidence > 0:
        if confidence is None or np.shape(confidence) != visible.shape:
            raise ValueError(f"confidence: expected an array of shape {visible.shape} with "
                             f"min_confidence, got "
                             f"{None if confidence is None else np.shape(confidence)}")
        visible = visible & (np.asarray(confidence) >= min_confidence)
    if which == "all":
        return visible
    if which == "object":
        return visible & fg
    if which == "background":
        return visible & ~fg
    raise ValueError(f"which: expected one of {', '.join(WHICH)}, got {which!r}")


def cloud(calib, disparity, image, layer, mask, confidence=None) -> dict:
    """The points of the pixels of ``mask`` with a finite depth.

    Parameters
    ----------
    calib : lss_kernels.calib.Calibration
    disparity : ndarray, float, shape (H, W)
        Left-view disparity.
    image : ndarray, shape (H, W, 3)
        The left image: float in [0, 1] or uint8.
    layer : ndarray, integer, shape (H, W)
        Each pixel's layer index (0 to 255).
    mask : ndarray, bool, shape (H, W)
        The pixels wanted (:func:`select`).
    confidence : ndarray, float, shape (H, W), optional
        Each pixel's confidence (``Result.confidence``), carried by its point.

    Returns
    -------
    dict
        ``xyz`` float32 ``(N, 3)``, ``rgb`` uint8 ``(N, 3)``, ``layer`` uint8 ``(N,)`` and,
        with ``confidence``, ``confidence`` float32 ``(N,)``, in row-major pixel order.
    """
    disparity = np.asarray(disparity)
    shape = disparity.shape
    image = np.asarray(image)
    layer = np.asarray(layer)
    if image.shape != shape + (3,):
        raise ValueError(f"image: expected an array of shape {shape + (3,)}, got {image.shape}")
    if layer.shape != shape or not np.issubdtype(layer.dtype, np.integer) and layer.dtype != bool:
        raise ValueError(f"layer: expected integers of shape {shape}, got {layer.dtype} of "
                         f"shape {layer.shape}")
    if layer.size and (layer.min() < 0 or layer.max() > 255):
        raise ValueError(f"layer: expected indices in [0, 255], got [{layer.min()}, "
                         f"{layer.max()}]")
    if confidence is not None and np.shape(confidence) != shape:
        raise ValueError(f"confidence: expected an array of shape {shape}, got "
                         f"{np.shape(confidence)}")
    xyz, kept = calib.points(disparity, mask)
    rgb = image if image.dtype == np.uint8 else np.round(np.clip(image, 0, 1) * 255)
    points = {"xyz": xyz, "rgb": rgb[kept].astype(np.uint8),
              "layer": layer[kept].astype(np.uint8)}
    if confidence is not None:
        points["confidence"] = np.asarray(confidence, np.float32)[kept]
    return points


def write_ply(path, points: dict) -> Path:
    """Write :func:`cloud`'s points as a binary little-endian PLY; returns ``path``."""
    from plyfile import PlyData, PlyElement
    xyz, rgb, layer = points["xyz"], points["rgb"], points["layer"]
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("green", "u1"),
              ("blue", "u1"), ("layer", "u1")]
    if "confidence" in points:
        fields.append(("confidence", "<f4"))
    vertex = np.empty(len(xyz), dtype=fields)
    vertex["x"], vertex["y"], vertex["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    vertex["red"], vertex["green"], vertex["blue"] = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    vertex["layer"] = layer
    if "confidence" in points:
        vertex["confidence"] = points["confidence"]
    PlyData([PlyElement.describe(vertex, "vertex")], text=False, byte_order="<").write(
        str(path))
    return Path(path)


def read_ply(path) -> dict:
    """A PLY written by :func:`write_ply` as :func:`cloud`'s dict."""
    from plyfile import PlyData
    vertex = PlyData.read(str(path))["vertex"].data
    points = {"xyz": np.stack([vertex["x"], vertex["y"], vertex["z"]], axis=1).astype(
        np.float32), "rgb": np.stack([vertex["red"], vertex["green"], vertex["blue"]], axis=1),
        "layer": np.asarray(vertex["layer"])}
    if "confidence" in vertex.dtype.names:
        points["confidence"] = np.asarray(vertex["confidence"])
    return points
