"""The left-view layer map and the occlusion rule for any number of ordered layers.

Layers are numbered by what they are to the chosen object: ``BACKGROUND`` (0, behind it:
Theta_2), ``OBJECT`` (1, phi > 0: Theta_1) and ``FRONT`` (2, in front of it:
:mod:`lss_kernels.model.front`).  A left-view pixel ``x`` with disparity ``d`` is seen by the
right camera at ``r = x - d`` (Middlebury convention).  It is occluded when a pixel of another
layer, nearer (larger disparity), covers ``r`` in the right view: the ray cast of Sec. 2,
applied to each pair of layers.  A nearer pixel ``x'`` covers the right-view interval from
``x' - d(x') - 1/2`` to ``x' - d(x') + 1/2``, stretched to the next pixel's position when
``x' + 1`` belongs to the same layer (a surface seen in the right view is continuous along
the row).  With two layers this is the z-buffer of the two-layer model: a whole-pixel jump
``t`` hides exactly ``t`` pixels beside the object's left edge.

The rule runs as one kernel over the left view's pixels (each walks the ``reach`` pixels to its
right: no nearer pixel farther than the disparity range can cover it); its numpy
specification is :func:`lss_kernels.reference.layers.occlusion_by_layers`.
"""
import numpy as np
import taichi as ti

__all__ = ["BACKGROUND", "FRONT", "OBJECT", "front_in_left_view", "occlusion_by_layers"]

BACKGROUND, OBJECT, FRONT = 0, 1, 2


@ti.kernel
def _occlusion(disparity: ti.types.ndarray(), layers: ti.types.ndarray(),
               occluders: ti.types.ndarray(), reach: ti.i32, out: ti.types.ndarray()):
    height, width = disparity.shape[0], disparity.shape[1]
    for y, x in ti.ndrange(height, width):
        d = disparity[y, x]
        r = ti.cast(x, ti.f32) - d
        own = layers[y, x]
        hit = 0
        for k in range(1, reach + 1):
            u = x + k
            if u < width and hit == 0:
                if occluders[y, u] != 0 and layers[y, u] != own and disparity[y, u] > d:
                    a = ti.cast(u, ti.f32) - disparity[y, u]
                    b = a
                    if u + 1 < width:
                        if occluders[y, u + 1] != 0 and layers[y, u + 1] == layers[y, u]:
                            b = ti.cast(u + 1, ti.f32) - disparity[y, u + 1]
                    if ti.min(a, b) - 0.5 <= r <= ti.max(a, b) + 0.5:
                        hit = 1
        out[y, x] = hit


def occlusion_by_layers(disparity, layers, occluders=None) -> np.ndarray:
    """Left-view pixels hidden from the right camera by a nearer pixel of another layer.

    Parameters
    ----------
    disparity : array ``(H, W)``
        Left-view disparity of every pixel (finite), left-view pixels.
    layers : integer array ``(H, W)``
        Each pixel's layer.
    occluders : boolean array ``(H, W)``, optional
        The pixels that may hide others (default: all).

    Returns
    -------
    ndarray of bool ``(H, W)``
    """
    disparity = np.ascontiguousarray(disparity, dtype=np.float32)
    if disparity.ndim != 2 or not np.isfinite(disparity).all():
        raise ValueError(f"disparity: expected a finite (H, W) array, got shape "
                         f"{disparity.shape}")
    layers = np.ascontiguousarray(layers, dtype=np.int32)
    occluders = (np.ones(disparity.shape, np.int32) if occluders is None
                 else np.ascontiguousarray(occluders, dtype=np.int32))
    for name, a in (("layers", layers), ("occluders", occluders)):
        if a.shape != disparity.shape:
            raise ValueError(f"{name}: expected shape {disparity.shape}, got {a.shape}")
    spread = float(disparity.max() - disparity.min()) if disparity.size else 0.0
    out = np.zeros(disparity.shape, np.int32)
    _occlusion(disparity, layers, occluders, int(np.ceil(spread)) + 2, out)
    return out.astype(bool)


def front_in_left_view(front: np.ndarray, first: np.ndarray) -> tuple:
    """``(mask, disparity)``: the front layer seen in the left view.

    ``front`` (bool) and ``first`` (its cyclopean disparity c) are cyclopean planes; a front
    pixel at ``x_c`` is seen by the left camera at ``x_c + c`` with the left-view disparity
    ``2 c`` (nearest wins where two land on one pixel); a one-pixel gap between two front
    pixels of a row (a slanted surface stretched in the left view) is filled from its
    neighbours."""
    H, W = front.shape
    mask = np.zeros((H, W), bool)
    disparity = np.full((H, W), -np.inf, np.float32)
    ys, xs = np.nonzero(front)
    c = first[ys, xs].astype(np.float32)
    xl = np.rint(xs + c).astype(np.int64)
    keep = (xl >= 0) & (xl < W)
    ys, xl, c = ys[keep], xl[keep], c[keep]
    mask[ys, xl] = True
    np.maximum.at(disparity, (ys, xl), 2.0 * c)
    gap = np.zeros_like(mask)
    gap[:, 1:-1] = ~mask[:, 1:-1] & mask[:, :-2] & mask[:, 2:]
    gy, gx = np.nonzero(gap)
    disparity[gy, gx] = np.maximum(disparity[gy, gx - 1], disparity[gy, gx + 1])
    mask |= gap
    return mask, np.where(mask, disparity, 0.0).astype(np.float32)
