"""Planes stored in blocks of horizontally adjacent pixels, so that the CPU runs stencils in
SIMD lanes.

Taichi's CPU backend emits scalar code per loop index, and LLVM's SLP vectoriser packs it into
vector instructions only when the results are stored as whole vectors: never through
``a[y, x + l]`` in a scalar field.  A *lane plane* is a vector field of shape
``(H, ceil(W / L))`` whose element ``[y, b]`` holds the ``L`` pixels ``x = b L .. b L + L - 1``
of row ``y``.  The separable filters run a block per loop index: the row pass reads the
block's window of a plane once and stores whole blocks; the column pass loads and stores
whole blocks.  LLVM packs their sums into the lanes, about three times as fast as scalar
code for phi's derivatives and curvature at 400x300 on a 2-core CPU.  Kernels that run per
block load a block with :func:`block` (from a plain plane too) and its x coordinates with
:func:`columns`.

``L`` is 8 (one AVX register of f32) on the CPU and 1 on GPUs, where each thread is already
one pixel and a lane plane is an ordinary plane.  Lanes past the image's right edge are
computed like the others (from reflected pixels) and never stored as pixels.
"""
import numpy as np
import taichi as ti

__all__ = ["lanes_for_arch", "block_count", "lane_plane", "block", "columns", "take",
           "to_image"]


def lanes_for_arch() -> int:
    """Pixels per block for the arch Taichi runs on: 8 on the CPU, 1 elsewhere."""
    return 8 if ti.lang.impl.current_cfg().arch == ti.cpu else 1


def block_count(width, lanes):
    """Blocks of ``lanes`` pixels that cover ``width`` pixels (the last may be partial)."""
    return (int(width) + lanes - 1) // lanes


def lane_plane(pool, height, width, lanes, margin_rows=0, bucket=False):
    """A lane plane of ``height`` rows (plus ``margin_rows`` above and below, at negative
    and past-the-end row indices) and ``width`` pixels, in blocks of ``lanes``; ``bucket``:
    in the pool's bucket tree (``height`` and ``width`` those of the bucket)."""
    shape = (int(height) + 2 * margin_rows, block_count(width, lanes))
    offset = (-margin_rows, 0) if margin_rows else None
    return pool.vector(lanes, ti.f32, shape, offset=offset, bucket=bucket)


@ti.func
def block(f: ti.template(), y, b, lanes: ti.template(), width):
    """Block ``b`` of row ``y`` (``lanes`` pixels, as a vector) of a lane plane, or gathered
    from a plain scalar plane of an image ``width`` pixels wide (pixels past its right edge
    repeat the last one)."""
    value = ti.Vector.zero(ti.f32, lanes)
    if ti.static(isinstance(f, ti.MatrixField)):
        value = f[y, b]
    else:
        last = width - 1
        value = ti.Vector([f[y, ti.min(b * lanes + lane, last)]
                           for lane in ti.static(range(lanes))])
    return value


@ti.func
def columns(b, lanes: ti.template()):
    """The x coordinates of block ``b``'s pixels, as a float vector."""
    return ti.Vector([ti.cast(b * lanes + lane, ti.f32) for lane in ti.static(range(lanes))])


@ti.func
def take(window: ti.template(), start: ti.template(), lanes: ti.template()):
    """Entries ``start .. start + lanes - 1`` of a local vector (a block's window) as a
    block: a block moved by a compile-time offset within the window it was read from.
    The window is a template, not copied at each call: the front end visits a quarter
    fewer nodes."""
    return ti.Vector([window[i] for i in ti.static(range(start, start + lanes))])


def to_image(f, height, width, margin_rows=0):
    """The first ``height`` rows and ``width`` pixels of a lane plane as a float32 array
    (without its margin rows)."""
    blocks = f.to_numpy()
    rows = blocks.reshape(blocks.shape[0], -1)[margin_rows:margin_rows + height, :width]
    return np.ascontiguousarray(rows, dtype=np.float32)
