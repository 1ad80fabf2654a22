"""delta_theta and the left-view rendering against hand-built two-plane cases."""
import numpy as np
import pytest
import taichi as ti

from lss_kernels.reference import kernels as ref
from lss_kernels.reference import refine as after
from lss_kernels.kernels.backend import FieldPool

H, W, C = 12, 64, 16
X = np.broadcast_to(np.arange(W, dtype=np.float64), (H, W))


@pytest.fixture(scope="module")
def geometry(ti_arch):
    from lss_kernels.model.occlusion import OcclusionGeometry
    from lss_kernels.model.shapes import GlobalShapes, WeightPlanes
    pool = FieldPool()
    occ = OcclusionGeometry(pool, H, W, C)
    shapes = GlobalShapes(pool, H, W)
    phi, phi_x, ones, zeros, target = (pool.field(ti.f32, (H, W)) for _ in range(5))
    pool.finalize()
    ones.from_numpy(np.ones((H, W), np.float32))
    only = (WeightPlanes(ones, zeros), WeightPlanes(zeros, ones))   # Theta_1's rows, Theta_2's

    def setup(theta1, theta2, fg, offset=0.0):
        """Theta_j as exact planes (fitted from their own values), phi = 0.01 x signed
        distance of the foreground columns ``fg`` (a boolean over x), plus ``offset``."""
        y, x = np.mgrid[0:H, 0:W].astype(np.float64)
        for j, th in enumerate((theta1, theta2)):
            target.from_numpy(th(x, y).astype(np.float32))
            shapes.fit(only[j], target)
        cols = np.arange(W)
        edges = np.flatnonzero(np.diff(fg.astype(int))) + 0.5
        dist = np.min(np.abs(cols[:, None] - edges[None, :]), axis=1)
        p = 0.01 * np.where(fg, dist, -dist) + offset
        phi.from_numpy(np.broadcast_to(p, (H, W)).astype(np.float32))
        phi_x.from_numpy(np.broadcast_to(np.gradient(p), (H, W)).astype(np.float32))
        occ.compute(shapes, phi_x, 1)
        occ.refresh_phi_plus(phi)
        occ.render_left(shapes, phi)
        return p
    yield occ, shapes, setup
    pool.destroy()


def _fg_band(lo, hi):
    return (np.arange(W) >= lo) & (np.arange(W) < hi)


def test_occluded_extent_equals_the_jump_on_both_sides(geometry):
    occ, _, setup = geometry
    fg = _fg_band(20, 40)
    phi = setup(lambda x, y: 10 + 0 * x, lambda x, y: 4 + 0 * x, fg)
    dt = occ.extent.image(occ.delta_theta)[0]
    assert np.allclose(dt[:20], 6.0) and np.allclose(dt[40:], -6.0)
    visible_bg = (phi < 0) & (occ.extent.image(occ.phi_plus)[0] < 0)
    hidden = np.flatnonzero((phi < 0) & ~visible_bg)
    # the jump is 6 cyclopean pixels: 6 background pixels left of the left boundary and 6
    # right of the right boundary are occluded
    assert hidden.tolist() == list(range(14, 20)) + list(range(40, 46))


def test_ray_cast_on_a_slanted_background_matches_the_analytic_intersection(geometry):
    occ, _, setup = geometry
    k = 0.25
    th1 = lambda x, y: 12 + 0 * x
    th2 = lambda x, y: 2 + k * (x - 32) / 8
    fg = _fg_band(20, 44)
    p = setup(th1, th2, fg)
    got = occ.extent.image(occ.delta_theta)
    s = np.sign(np.gradient(p))
    # t = Theta_1 - Theta_2(x - s t)  =>  t (1 - s k / 8) = 12 - 2 - k (x - 32) / 8
    t = (10 - k * (X - 32) / 8) / (1 - s * k / 8)
    want = np.where(s != 0, s * t, 0)
    np.testing.assert_allclose(got, want, atol=1e-4)
    np.testing.assert_allclose(got, ref.delta_theta(th1, th2, np.broadcast_to(np.gradient(p),
                                                                           (H, W))), atol=1e-4)
    # the release's approximation (Theta_1 - Theta_2 at x) differs on a slanted background
    assert np.abs(got - s * (th1(X, 0) - th2(X, 0))).max() > 0.1


def test_ray_cast_runs_the_fixed_point_iteration_to_its_last_step(geometry):
    """A steep background (dTheta_2/dx = 1/2) leaves the fixed-point iteration short of the
    intersection after its 6 steps; the kernel, which leaves the loop once a step repeats
    its input, must still give what all 6 steps give."""
    occ, _, setup = geometry
    th1 = lambda x, y: 14 + 0 * x
    th2 = lambda x, y: 4 + 0.5 * (x - 32)
    p = setup(th1, th2, _fg_band(22, 44))
    px = np.broadcast_to(np.gradient(p), (H, W))
    got = occ.extent.image(occ.delta_theta)
    six = ref.delta_theta(th1, th2, px, steps=6, c_cap=2.0 * C)
    exact = ref.delta_theta(th1, th2, px, steps=200, c_cap=2.0 * C)
    assert np.abs(six - exact).max() > 0.05          # the 6-step result is not converged
    np.testing.assert_allclose(got, six, atol=2e-4)


def test_no_jump_no_occlusion(geometry):
    occ, _, setup = geometry
    setup(lambda x, y: 4 + 0 * x, lambda x, y: 9 + 0 * x, _fg_band(20, 40))
    assert np.all(occ.extent.image(occ.delta_theta) == 0)


def test_left_view_rendering_of_two_fronto_parallel_planes(geometry):
    occ, _, setup = geometry
    setup(lambda x, y: 10 + 0 * x, lambda x, y: 4 + 0 * x, _fg_band(20, 40))
    fg = occ.extent.image(occ.foreground_left)[0].astype(bool)
    occl = occ.extent.image(occ.occlusion_left)[0].astype(bool)
    d = occ.extent.image(occ.disparity_left)[0]
    # x_left = x_c + c: the cyclopean band [20, 40) appears at [30, 50) in the left view
    assert np.flatnonzero(fg).tolist() == list(range(30, 50))
    assert np.allclose(d[fg], 20.0) and np.allclose(d[~fg], 8.0)
    # seen by the left camera, hidden from the right: left of the foreground only, as wide
    # as the left-view disparity jump (20 - 8 = 12)
    assert np.flatnonzero(occl).tolist() == list(range(18, 30))
    assert not (occl & fg).any()


def test_occluded_strip_is_as_wide_as_a_whole_pixel_jump_whatever_the_rounding(geometry):
    """Theta_1 = 7.5, Theta_2 = 6 (+1e-4): a jump of 3 left-view pixels.  The foreground's
    first left pixel (27, at x_c = 19.5) and the right ray of the strip's first pixel (24)
    meet phi at the same point, so a test of phi there would fall either way with the
    rounding of Theta_2; the strip must still be 3 pixels, as the rendered jump says."""
    occ, _, setup = geometry
    for eps in (0.0, 1e-4, -1e-4):
        for offset in (5e-7, -5e-7):
            setup(lambda x, y: 7.5 + 0 * x, lambda x, y: 6 + eps + 0 * x, _fg_band(20, 40),
                  offset=offset)
            fg = occ.extent.image(occ.foreground_left)[0].astype(bool)
            occl = occ.extent.image(occ.occlusion_left)[0].astype(bool)
            first = np.flatnonzero(fg)[0]
            assert first == (27 if offset > 0 else 28)
            assert np.flatnonzero(occl).tolist() == list(range(first - 3, first)), (eps, offset)


# ------------------------------------------------------------ strips against the refined map
def _strips(geometry, fg, surface, refined, matched=None, near=6, far=20):
    """``measure_strips`` on hand-made left-view planes (``matched``: every pixel if None);
    returns the occlusion mask and the numpy specification's."""
    occ = geometry[0]
    matched = np.ones(fg.shape, bool) if matched is None else matched
    occ.foreground_left.from_numpy(occ.extent.padded(fg.astype(np.int32)))
    occ.disparity_left.from_numpy(occ.extent.padded(surface.astype(np.float32)))
    # two spare planes hold the refined map and the matched pixels
    occ.delta_theta.from_numpy(occ.extent.padded(refined.astype(np.float32)))
    occ.phi_plus.from_numpy(occ.extent.padded(matched.astype(np.float32)))
    occ.measure_strips(occ.delta_theta, occ.phi_plus, near, far)
    got = occ.extent.image(occ.occlusion_left).astype(bool)
    return got, after.occluded_strips(fg, surface, refined, matched, near, far)


def _row_of(mask):
    return [np.flatnonzero(row).tolist() for row in mask]


def test_strips_follow_the_refined_background_beside_the_object(geometry):
    # a fronto-parallel object at 30 px over a background quadratic at 10 px; in rows 0-3 the
    # refined map puts the visible background 8 px nearer (a box the quadratic missed)
    fg = np.zeros((H, W), bool)
    fg[:, 36:] = True
    surface = np.where(fg, 30.0, 10.0)
    refined = surface.copy()
    refined[:6][~fg[:6]] += 8.0
    matched = np.ones((H, W), bool)
    matched[4:6] = False                        # rows 4, 5: the refinement filled them in
    got, want = _strips(geometry, fg, surface, refined, matched)
    rows = _row_of(got)
    assert rows[0] == list(range(24, 36))       # 30 - 18: twelve pixels, not twenty
    assert rows[4] == rows[6] == list(range(16, 36))   # no match there, or no box: twenty
    np.testing.assert_array_equal(got, want)


def test_a_short_run_hides_no_more_than_its_own_footprint(geometry):
    fg = np.zeros((H, W), bool)
    fg[0, 40:45] = True                          # 5 px of foreground, 20 px in front
    fg[1, 40:60] = True
    surface = np.where(fg, 30.0, 10.0)
    got, want = _strips(geometry, fg, surface, surface)
    rows = _row_of(got)
    # the right camera sees the short run over [20, 25) of the background: x - 10 in
    # [40 - 30, 45 - 30)
    assert rows[0] == list(range(20, 25))
    assert rows[1] == list(range(20, 40))
    np.testing.assert_array_equal(got, want)


def test_strips_keep_the_quadratic_without_evidence_or_past_the_border(geometry):
    fg = np.zeros((H, W), bool)
    fg[0, 18:40] = True                          # the strip reaches past the left border
    fg[1, 20:24] = fg[1, 34:50] = True           # the second run's strip ends on the first
    fg[2, 0:30] = True                           # a run at the border hides nothing
    surface = np.where(fg, 30.0, 10.0)
    refined = np.where(fg, 30.0, 14.0)           # the refined background disagrees everywhere
    got, want = _strips(geometry, fg, surface, refined)
    rows = _row_of(got)
    assert rows[0] == list(range(0, 18))         # clipped at the border, no window: 20 px
    # row 1, the 4 px run: no window left of the border, its footprint hides [0, 4); the
    # 16 px run: the background 4 px nearer over [0, 7] and then [0, 11], so 16 px, less
    # the first run's pixels
    assert rows[1] == [0, 1, 2, 3, 18, 19] + list(range(24, 34))
    np.testing.assert_array_equal(got, want)
    assert rows[2] == []


def test_a_slanted_background_without_matches_keeps_its_quadratics_strip(geometry):
    # the background falls towards the object (10 px at its edge, 5.2 px 24 px away): the
    # strip ends where the jump to the quadratic there is its width, 30 - 4.8 = 25.2 px,
    # whether the refined map agrees with the quadratic or no pixel holds a match
    fg = np.zeros((H, W), bool)
    fg[:, 36:] = True
    surface = np.where(fg, 30.0, 10.0 + 0.2 * (X - 36))
    matched_none = np.zeros((H, W), bool)
    got, want = _strips(geometry, fg, surface, surface + 3.0 * ~fg, matched_none)
    agreed, _ = _strips(geometry, fg, surface, surface)
    assert _row_of(got)[0] == list(range(11, 36))          # 25 px, not the edge's 20
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(got, agreed)


def test_a_narrow_run_tilted_towards_the_camera_by_the_border_hides_nothing(geometry):
    fg = np.zeros((H, W), bool)
    fg[0, 2:4] = True
    surface = np.where(fg, 0.0, 10.0)
    surface[0, 2:4] = (12.0, 20.0)               # its right end lies 16 px left of the image
    got, want = _strips(geometry, fg, surface, surface)
    assert not got.any() and not want.any()


@pytest.mark.slow
def test_a_solve_measures_its_strips_against_the_refined_box(ti_arch):
    """A box at 16 px stands between the object (24 px) and the wall (8 px), beside the
    object's left edge: one quadratic puts the wall there, and its strips are 16 px wide
    where the jump is 8.  The strips measured against the refined background score higher,
    and without the refinement the output keeps the quadratics' strips."""
    from lss_kernels import Params, Solver
    from lss_kernels.metrics import score
    from lss_kernels.model.offset import to_user_left
    from lss_kernels.scenes import make_scene
    scene = make_scene("easy", props=({"d": 16.0, "box": (41.0, 60.0, 15.0, 30.0)},),
                       outline="rectangle", ellipse=(80.0, 48.0, 24.0, 30.0))
    solver = Solver(scene.left, scene.right, scene.d_max, scene.init_ellipse)
    try:
        solver.run()
        surface, quadratics, foreground = solver.left_view()
        _, strips, foreground_again, refined = solver.left_view(refine=True)
        matched = to_user_left(solver.extent.image(solver.refinement.weight), solver.shift)
    finally:
        solver.close()
    np.testing.assert_array_equal(foreground, foreground_again)
    np.testing.assert_array_equal(strips, after.occluded_strips(
        foreground, surface, refined, matched > 0, *Params().strip_window))
    f1 = lambda occlusion: score(refined, occlusion, scene)["occ_f1"]
    assert f1(strips) >= f1(quadratics) + 0.1, (f1(strips), f1(quadratics))
    plain = Solver(scene.left, scene.right, scene.d_max, scene.init_ellipse,
                   params=Params(refine=False, max_iterations=1))
    try:
        plain.run()
        np.testing.assert_array_equal(plain.result().occlusion, plain.left_view()[1])
    finally:
        plain.close()
