"""The curve and surface helpers of lss_kernels.kernels.curves against small numpy
references."""
import numpy as np
import pytest
import taichi as ti

from lss_kernels.kernels.curves import (curve_minima, parabola_vertex, quadratic,
                                        vertex_offset)


def _vertex_reference(below, at, above, min_curvature):
    den = below - 2.0 * at + above
    return np.where(den > min_curvature, 0.5 * (below - above) / np.where(den == 0, 1, den),
                    0.0)


@pytest.mark.parametrize("min_curvature", [0.0, 1e-12, 0.5])
def test_the_parabola_vertex_matches_numpy(ti_arch, min_curvature):
    rng = np.random.default_rng(5)
    samples = rng.uniform(-1, 1, (3, 200)).astype(np.float32)
    samples[:, :20] = 0.25                                      # flat: no vertex
    line = np.round(rng.uniform(-8, 8, (2, 10))) / 8                  # a line: none either
    samples[:, 20:30] = line[0] + line[1] * np.arange(3)[:, None]
    out = ti.field(ti.f32, 200)
    inp = ti.field(ti.f32, (3, 200))
    inp.from_numpy(samples)

    @ti.kernel
    def vertices(min_curvature: ti.f32):
        for i in out:
            out[i] = parabola_vertex(inp[0, i], inp[1, i], inp[2, i], min_curvature)

    vertices(min_curvature)
    want = _vertex_reference(*samples.astype(np.float64), min_curvature)
    np.testing.assert_allclose(out.to_numpy(), want, rtol=1e-5, atol=1e-6)
    assert not want[:30].any()
    # the host's form, and a parabola's own vertex
    host = [vertex_offset(*samples[:, i].astype(np.float64), min_curvature) for i in range(200)]
    np.testing.assert_allclose(host, want, rtol=1e-12, atol=0)
    c = np.array([-1.0, 0.0, 1.0])
    assert vertex_offset(*((c - 0.3) ** 2), 0.0) == pytest.approx(0.3)


def test_the_curve_minima_match_numpy(ti_arch):
    rng = np.random.default_rng(6)
    n, none = 9, 1e9
    curves = np.round(rng.uniform(0, 4, (4, 5, n))).astype(np.float32)   # ties included
    curves[0, 0] = none                     # no value below none
    curves[0, 1, 2:] = none                 # one value, and its neighbour
    field = ti.field(ti.f32, curves.shape)
    field.from_numpy(curves)
    got = ti.Vector.field(4, ti.f32, curves.shape[:2])

    @ti.kernel
    def minima(count: ti.i32):
        for y, x in got:
            best, kb, second, total = curve_minima(field, y, x, count, none)
            got[y, x] = ti.Vector([best, kb, second, total])

    for count in (n, 3):
        minima(count)
        c = curves[..., :count].astype(np.float64)
        kb = np.where(c.min(axis=-1) < none, c.argmin(axis=-1), -1)
        k = np.arange(count)
        away = np.abs(k - kb[..., None]) >= 2
        second = np.minimum(np.where(away, c, none).min(axis=-1), none)
        want = np.stack([np.minimum(c.min(axis=-1), none), kb, second, c.sum(axis=-1)], -1)
        np.testing.assert_allclose(got.to_numpy(), want, rtol=1e-6)
    assert got.to_numpy()[0, 0, 1] == -1 and got.to_numpy()[0, 1, 2] == none


def test_the_quadratic_matches_numpy(ti_arch):
    rng = np.random.default_rng(7)
    theta = rng.uniform(-2, 2, 6).astype(np.float32)
    xy = rng.uniform(-1, 1, (2, 50)).astype(np.float32)
    inp = ti.field(ti.f32, (2, 50))
    inp.from_numpy(xy)
    out = ti.field(ti.f32, 50)

    @ti.kernel
    def evaluate(t: ti.types.vector(6, ti.f32)):
        for i in out:
            out[i] = quadratic(t, inp[0, i], inp[1, i])

    evaluate(ti.Vector(theta.tolist()))
    x, y = xy.astype(np.float64)
    U = np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)])
    np.testing.assert_allclose(out.to_numpy(), theta.astype(np.float64) @ U, rtol=1e-5,
                               atol=1e-5)
