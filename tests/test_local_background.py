"""The local background (Params.local_background, GlobalShapes.fit_local) against a numpy
reference of its tile systems, and on a background of two surfaces that one quadratic cannot
follow."""
import numpy as np
import pytest
import taichi as ti

from lss_kernels.kernels.backend import FieldPool
from lss_kernels.model.quadratic import basis
from lss_kernels.model.shapes import (LOCAL_GAP, LOCAL_NEAR, LOCAL_PRIOR, TILE,
                                      GlobalShapes, WeightPlanes)
from lss_kernels.params import PHI_SCALE


@ti.kernel
def _background(shapes: ti.template(), out: ti.template()):
    for y, x in out:
        out[y, x] = shapes.value(1, ti.cast(x, ti.f32), ti.cast(y, ti.f32))


@ti.kernel
def _background_of_size(shapes: ti.template(), out: ti.template()):
    for y, x in out:
        out[y, x] = shapes.value_of_size(1, ti.cast(x, ti.f32), ti.cast(y, ti.f32))


@ti.data_oriented
class _Rows(WeightPlanes):
    """Row weights with the level set's phi, as the solver's RegionWeights have it."""

    def __init__(self, weight_fg, weight_bg, phi):
        super().__init__(weight_fg, weight_bg)
        self.phi = phi


def _phi(wf):
    """phi of the object ``wf > 0``: PHI_SCALE times the chessboard distance to it, negative
    outside (enough for the rows the local fits leave out)."""
    h, w = wf.shape
    ys, xs = np.nonzero(wf > 0)
    y, x = np.mgrid[0:h, 0:w]
    dy = np.maximum(np.maximum(ys.min() - y, y - ys.max()), 0)
    dx = np.maximum(np.maximum(xs.min() - x, x - xs.max()), 0)
    return np.where(wf > 0, 1.0, -np.maximum(dy, dx)) * PHI_SCALE


def _solve(h, w, wf, wb, target, local):
    pool = FieldPool()
    shapes = GlobalShapes(pool, h, w, local=local)
    fields = [pool.field(ti.f32, (h, w)) for _ in range(6)]
    pool.finalize()
    for f, a in zip(fields, (wf, wb, target)):
        f.from_numpy(a.astype(np.float32))
    fields[5].from_numpy(_phi(wf).astype(np.float32))
    rows = _Rows(fields[0], fields[1], fields[5])
    shapes.fit(rows, fields[2])
    theta = shapes.theta.to_numpy().astype(np.float64)
    if local:
        shapes.fit_local(rows, fields[2])
    _background(shapes, fields[3])
    _background_of_size(shapes, fields[4])
    out = (theta, fields[3].to_numpy(), fields[4].to_numpy(),
           shapes.local_theta.to_numpy() if local else None)
    pool.destroy()
    return out


def _normalised_basis(h, w):
    s = max(h, w) / 2.0
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    return basis((x - (w - 1) / 2.0) / s, (y - (h - 1) / 2.0) / s)


def _reference_local(h, w, wf, wb, target, theta, local):
    """Each first-level tile's quadratic: the Gaussian-weighted sum of its neighbours' normal
    equations (of the background rows more than LOCAL_NEAR behind Theta_1 and more than
    LOCAL_GAP px from the boundary) plus LOCAL_PRIOR rows of the whole background that
    target Theta_2."""
    U = _normalised_basis(h, w)
    wb = wb.astype(np.float32).astype(np.float64)
    d = target.astype(np.float32).astype(np.float64)
    n_g = max((wb > 0).sum(), 1)
    A_g = np.einsum("hwa,hw,hwb->ab", U, wb, U)
    prior = A_g * LOCAL_PRIOR / n_g
    wb = np.where(d > U @ theta[0] - LOCAL_NEAR, 0.0, wb)
    wb = np.where(_phi(wf).astype(np.float32) > -LOCAL_GAP * PHI_SCALE, 0.0, wb)
    rows, columns = -(-h // TILE), -(-w // TILE)
    A = np.zeros((rows, columns, 6, 6))
    b = np.zeros((rows, columns, 6))
    for ty in range(rows):
        for tx in range(columns):
            sl = np.s_[ty * TILE:(ty + 1) * TILE, tx * TILE:(tx + 1) * TILE]
            u, wt = U[sl].reshape(-1, 6), wb[sl].reshape(-1)
            A[ty, tx] = (u * wt[:, None]).T @ u
            b[ty, tx] = (u * wt[:, None]).T @ d[sl].reshape(-1)
    out = np.zeros((rows, columns, 6))
    for ty in range(rows):
        for tx in range(columns):
            M, r = prior.copy(), prior @ theta[1]
            for dy in range(-local, local + 1):
                for dx in range(-local, local + 1):
                    if 0 <= ty + dy < rows and 0 <= tx + dx < columns:
                        g = np.exp(-(dy * dy + dx * dx) * 2.0 / local ** 2)
                        M += g * A[ty + dy, tx + dx]
                        r += g * b[ty + dy, tx + dx]
            out[ty, tx] = np.linalg.solve(M, r)
    return out


def _two_surfaces(h, w, split, rod=False):
    """A background at 10 px left of column ``split`` and on a slant right of it, an object
    at 30 px in the middle (no background rows); with ``rod``, a vertical rod at 40 px in
    front of it, outside the object, among the background's rows."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    target = np.where(x < split, 10.0, 20.0 + 0.05 * (x - split))
    wf = np.zeros((h, w))
    wf[h // 3:2 * h // 3, w // 3:w // 2] = 1.0
    target[wf > 0] = 30.0
    if rod:
        target[:, w // 4:w // 4 + 4] = 40.0
    wb = 1.0 - wf
    return wf, wb, target


def test_local_background_matches_numpy_reference(ti_arch):
    h, w = 70, 100
    rng = np.random.default_rng(3)
    wf, wb, target = _two_surfaces(h, w, 60, rod=True)
    wb = wb * rng.uniform(0.5, 1.5, (h, w))
    theta, _, _, local = _solve(h, w, wf, wb, target, 2)
    ref = _reference_local(h, w, wf, wb, target, theta, 2)
    # compare each tile's quadratic where it is used: over its own tile
    U = _normalised_basis(h, w)
    for ty in range(ref.shape[0]):
        for tx in range(ref.shape[1]):
            u = U[ty * TILE:(ty + 1) * TILE, tx * TILE:(tx + 1) * TILE].reshape(-1, 6)
            np.testing.assert_allclose(u @ local[ty, tx], u @ ref[ty, tx], atol=0.05)


def test_local_background_follows_two_surfaces(ti_arch):
    """One quadratic over a step of 10 px leaves pixels several px off on both sides; the
    local background is within a fraction of a pixel away from the step, and the value the
    kernels read (value, value_of_size) is the same."""
    h, w = 96, 160
    wf, wb, target = _two_surfaces(h, w, 96)
    _, global_map, _, _ = _solve(h, w, wf, wb, target, 0)
    _, local_map, local_of_size, _ = _solve(h, w, wf, wb, target, 2)
    away = (np.abs(np.arange(w) - 96) > 40)[None, :] & (wb > 0)
    assert np.abs(global_map - target)[away].max() > 2.0
    assert np.abs(local_map - target)[away].max() < 0.5
    np.testing.assert_allclose(local_of_size, local_map, atol=1e-3)
    # under the object the local background stays near its surroundings' surface (10 px)
    inside = wf > 0
    assert np.abs(local_map[inside] - 10.0).max() < 1.5


def test_local_background_leaves_out_what_stands_in_front(ti_arch):
    """A rod in front of the object among the background's rows moves the one quadratic;
    the local fits leave it out, and the background beside it stays at 10 px."""
    h, w = 96, 160
    wf, wb, target = _two_surfaces(h, w, 96, rod=True)
    _, local_map, _, _ = _solve(h, w, wf, wb, target, 2)
    beside = np.zeros((h, w), bool)
    beside[:, w // 4 - 12:w // 4 - 2] = True
    beside[:, w // 4 + 6:w // 4 + 16] = True
    beside &= wb > 0
    assert np.abs(local_map - 10.0)[beside].max() < 0.5


def test_local_background_off_is_one_quadratic(ti_arch):
    """``local=0`` reads Theta_2 itself."""
    h, w = 40, 56
    wf, wb, target = _two_surfaces(h, w, 30)
    theta, global_map, _, _ = _solve(h, w, wf, wb, target, 0)
    np.testing.assert_allclose(global_map, _normalised_basis(h, w) @ theta[1], atol=1e-3)


def test_local_background_parameter_is_validated():
    from lss_kernels import Params
    with pytest.raises(ValueError, match="local_background"):
        Params(local_background=-1)
    with pytest.raises(ValueError, match="local_background"):
        Params(local_background=2.5)


def test_local_background_leaves_out_the_rows_near_the_boundary(ti_arch):
    """Rows that the boundary has just given up (a ring around the object, between its depth
    and the background's) are no evidence of the background: within LOCAL_GAP px of the
    boundary they leave the local fits: the local background there is the one without the
    ring, but for the global fit's pull (the prior)."""
    h, w = 96, 160
    wf, wb, target = _two_surfaces(h, w, 120)
    ring = (np.abs(_phi(wf)) <= 3 * PHI_SCALE) & (wf == 0)
    _, without, _, _ = _solve(h, w, wf, wb, target, 2)
    target[ring] = 22.0
    global_theta, with_ring, _, _ = _solve(h, w, wf, wb, target, 2)
    _, global_map, _, _ = _solve(h, w, wf, wb, target, 0)
    assert np.abs(global_map - without)[ring].max() > 0.5      # the one quadratic moves
    assert np.abs(with_ring - without)[ring].max() < 0.2
