"""The layers' colour term (lss_kernels.model.appearance) against its numpy specification."""
import numpy as np
import pytest
import taichi as ti

from lss_kernels.kernels.backend import FieldPool
from lss_kernels.model.appearance import BINS, Appearance
from lss_kernels.model.shapes import GlobalShapes
from lss_kernels.params import PHI_SCALE, Params
from lss_kernels.reference.appearance import appearance_term


def _colours(rng, shape, levels):
    """Colours a quarter of a bin above a level: a mean of two of them never lies on a
    bin's edge, so float32 and float64 bin them alike."""
    return (rng.choice(levels, size=shape) + 0.25) / BINS


def _updates(left, right, phi, precision, weight, band, times=1):
    """``times`` runs of :meth:`Appearance.update` on the inputs (``Theta_1`` 2 px,
    ``Theta_2`` 1 px): each run's term and its band's sum of precisions."""
    h, w = phi.shape
    pool = FieldPool()
    shapes = GlobalShapes(pool, h, w)
    stage = Appearance(pool, h, w)
    views = [pool.vector(3, ti.f32, (h, w)) for _ in range(2)]
    phi_f, precision_f, out = (pool.field(ti.f32, (h, w)) for _ in range(3))
    pool.finalize()
    views[0].from_numpy(np.asarray(left, np.float32))
    views[1].from_numpy(np.asarray(right, np.float32))
    phi_f.from_numpy(phi)
    precision_f.from_numpy(precision)
    shapes.set(np.array([0, 0, 0, 0, 0, 2.0]), np.array([0, 0, 0, 0, 0, 1.0]))
    runs = []
    for _ in range(times):
        stage.update(views[0], views[1], phi_f, shapes, precision_f, out, weight, band)
        runs.append((out.to_numpy(), float(stage.sums.to_numpy()[2])))
    return runs


@pytest.mark.parametrize("weight", [0.06, 1.0])
def test_appearance_matches_numpy_reference(ti_arch, weight):
    rng = np.random.default_rng(3)
    h, w = 18, 40
    y, x = np.mgrid[0:h, 0:w]
    disc = (x - 22.0) ** 2 + (y - 9.0) ** 2 < 36.0
    # the object's colours from a few bins, the background's from others, shared noise
    left = np.where(disc[..., None], _colours(rng, (h, w, 3), [2, 3, 9]),
                    _colours(rng, (h, w, 3), [5, 6, 7, 9]))
    right = np.where(np.roll(disc, -4, axis=1)[..., None], _colours(rng, (h, w, 3), [2, 3]),
                     _colours(rng, (h, w, 3), [5, 6, 9]))
    # distances a quarter pixel off the half pixels: none lies on the band's edge
    distance = np.round(2.0 * (np.hypot(x - 22.0, y - 9.0) - 6.0)) / 2.0 + 0.25
    phi = (-distance * PHI_SCALE).astype(np.float32)
    precision = rng.uniform(0.0, 4.0, (h, w)).astype(np.float32)
    band = 4.0 * PHI_SCALE

    got = _updates(left, right, phi, precision, weight, band)[0][0]

    expected = appearance_term(left, right, phi.astype(np.float64), np.full((h, w), 2.0),
                               np.full((h, w), 1.0), precision.astype(np.float64), weight,
                               band)
    in_band = np.abs(phi) < band
    assert in_band.sum() > 100 and (np.abs(expected[in_band]) > 0).mean() > 0.9
    assert np.all(got[~in_band] == 0.0)
    np.testing.assert_allclose(got, expected, rtol=1e-4, atol=1e-6 * weight)


def test_the_colour_term_is_the_same_on_every_run(ti_arch):
    # the band's mean precision is a sum over many threads' pixels: summed in the threads'
    # order it differed in its last bits from run to run, and so did a point's whole solve
    rng = np.random.default_rng(4)
    h, w = 320, 320
    y, x = np.mgrid[0:h, 0:w]
    phi = ((150.0 - np.hypot(x - 160.0, y - 160.0)) * PHI_SCALE).astype(np.float32)
    precision = rng.uniform(0.0, 40.0, (h, w)).astype(np.float32)
    band = 16.0 * PHI_SCALE
    left, right = (rng.uniform(0.0, 1.0, (h, w, 3)) for _ in range(2))
    runs = _updates(left, right, phi, precision, 0.06, band, times=8)
    assert all(term.tobytes() == runs[0][0].tobytes() and total == runs[0][1]
               for term, total in runs)
    in_band = np.abs(phi) < band
    np.testing.assert_allclose(runs[0][1], precision[in_band].astype(np.float64).sum(),
                               rtol=1e-5)


def test_appearance_weight_is_validated():
    with pytest.raises(ValueError, match="appearance"):
        Params(appearance=-0.1)
    with pytest.raises(ValueError, match="appearance"):
        Params(appearance=float("nan"))


def test_a_clicked_weak_object_is_solved_with_the_colour_term(ti_arch):
    """A click starts the colour term (Params.appearance None -> APPEARANCE); a uniform
    mid-grey L over a textured background, whose matches are noise, is still found whole,
    with its occlusion."""
    from lss_kernels import Point, Solver
    from lss_kernels.metrics import score
    from lss_kernels.params import APPEARANCE
    from lss_kernels.scenes import _deepest_pixel, make_scene
    scene = make_scene("easy", seed=3, width=192, height=144, outline="L", noise=2 / 255,
                       texture_fg={"kind": "low_contrast", "brightness": 0.6,
                                   "amplitude": 4 / 255, "tint": 0.0})
    x, y = _deepest_pixel(scene.fg_left)
    solver = Solver(scene.left, scene.right, scene.d_max, Point(x, y))
    try:
        assert solver.params.appearance == APPEARANCE and solver.appearance is not None
        result = solver.run()
        term = solver.extent.image(solver.levelset.appearance)
    finally:
        solver.close()
    fg, truth = result.foreground, scene.fg_left
    assert (fg & truth).sum() >= 0.9 * (fg | truth).sum()
    assert score(result.disparity, result.occlusion, scene)["occ_f1"] >= 0.9
    assert np.count_nonzero(term) > 0
