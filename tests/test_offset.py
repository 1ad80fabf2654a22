"""Where the disparity grid starts (lss_kernels.model.offset): with ``Params.zero_floor`` (the
default) a pair whose background lies below 2 px is searched from 0 px, in fields of one plane
more, and what the solver takes and returns in the left view is in the user's columns either
way; every other pair, and every pair without it, keeps the authors' grid and fields."""
import numpy as np
import pytest

from lss_kernels import Params, solve
from lss_kernels.metrics import score
from lss_kernels.model.offset import (FLOOR_C, FLOOR_SHARE, SHIFT, floor_share, info_to_user,
                                      model_pair, search_range, to_model_left, to_model_start,
                                      to_user_left)
from lss_kernels.model.init import AUTO, Box, Point
from lss_kernels.params import c_max
from lss_kernels.scenes import make_scene


def test_the_model_pair_adds_offset_to_every_disparity():
    rng = np.random.default_rng(0)
    left, right = rng.random((2, 3, 12, 3)).astype(np.float32)
    model_left, model_right = model_pair(left, right, SHIFT)
    # a user pair (x_left, x_right = x_left - d) is the model's (x_left + SHIFT,
    # x_right - SHIFT): disparity d + 2 SHIFT, the same cyclopean column
    for x_left, d in ((5, 0), (7, 3), (11, 4)):
        x_right = x_left - d
        xl, xr = x_left + SHIFT, x_right - SHIFT
        assert xl - xr == d + 2 * SHIFT and (xl + xr) == (x_left + x_right)
        if xl < 12 and xr >= 0:
            np.testing.assert_array_equal(model_left[:, xl], left[:, x_left])
            np.testing.assert_array_equal(model_right[:, xr], right[:, x_right])
    np.testing.assert_array_equal(model_left[:, 0], left[:, 0])      # edges repeated
    np.testing.assert_array_equal(model_right[:, -1], right[:, -1])
    unmoved = model_pair(left, right, 0)
    np.testing.assert_array_equal(unmoved[0], left)
    np.testing.assert_array_equal(unmoved[1], right)


def test_left_view_planes_and_starts_move_between_the_views():
    plane = np.arange(24.0).reshape(3, 8)
    np.testing.assert_array_equal(to_user_left(to_model_left(plane, 1), 1)[:, :-1],
                                  plane[:, :-1])
    np.testing.assert_array_equal(to_model_left(plane, 1)[:, 1:], plane[:, :-1])
    np.testing.assert_array_equal(to_user_left(plane, 0), plane)
    assert to_model_start(Point(10.0, 4.0), 1) == Point(11.0, 4.0)
    assert to_model_start(Box(1.0, 2.0, 5.0, 6.0), 1) == Box(2.0, 2.0, 6.0, 6.0)
    assert to_model_start(AUTO, 1) == AUTO


def test_the_floor_share_counts_confident_pixels_below_the_floor():
    mean = FLOOR_C + np.array([[-1.0, -0.5, -0.1, 0.1], [1.0, 4.0, -0.5, -0.2]])
    precision = np.array([[1.0, 1.0, 1.0, 1.0], [1.0, 1.0, 0.0, 0.0]])
    assert floor_share(mean, precision) == pytest.approx(3 / 6)
    assert floor_share(mean, np.zeros_like(mean)) == 0.0


ZERO = Params()
OFF = Params(zero_floor=False)


def test_the_search_range_covers_zero_to_d_max():
    for d_max in (1, 2, 7, 8, 64, 65):
        assert c_max(d_max) == max(1, -(-d_max // 2))     # the authors' grid
        c = c_max(d_max) + 1                              # a pair searched from 0 px
        # from 0 px: c = 1 .. c_max are the disparities 2c - 2 SHIFT
        assert 2 * 1 - 2 * SHIFT <= 0 and 2 * c - 2 * SHIFT >= d_max
        assert 2 * (c - 1) - 2 * SHIFT < d_max          # no wider than needed


def test_a_pair_moves_only_with_the_option_and_enough_pixels_at_the_floor():
    mean = np.full((4, 5), FLOOR_C + 3.0)
    precision = np.ones_like(mean)
    mean.flat[:4] = FLOOR_C - 1.0                      # 4 of 20 = 0.20 at the floor
    assert 4 / 20 >= FLOOR_SHARE
    moved = search_range(mean, precision, True, 33)
    assert moved == {"zero_floor": True, "from_zero": True, "floor_share": 0.2,
                     "disparities": [0.0, 66.0]}
    assert search_range(mean, precision, False, 33)["disparities"] == [2.0, 66.0]
    mean.flat[:2] = FLOOR_C + 3.0                      # 0.10: the authors' grid
    assert not search_range(mean, precision, True, 33)["from_zero"]


def test_an_init_report_moves_to_the_user_frame():
    info = {"kind": "box", "box": [10.0, 2.0, 30.0, 20.0],
            "centre": {"point": [20.0, 11.0], "seed_cyclopean": [18, 12],
                       "seed_disparity": 14.0}, "area": 5}
    out = info_to_user(info, 1)
    assert out["box"] == [9.0, 2.0, 29.0, 20.0]
    assert out["centre"] == {"point": [19.0, 11.0], "seed_cyclopean": [18, 12],
                             "seed_disparity": 12.0}
    assert out["area"] == 5 and info["centre"]["seed_disparity"] == 14.0


@pytest.mark.slow
def test_a_background_at_zero_disparity_is_fitted_at_zero(ti_arch):
    # the search used to start at 2 px: a background at infinity was fitted there, with the
    # occluded extent 2 px short
    scene = _zero_background()
    result = solve(scene.left, scene.right, scene.d_max, scene.init_ellipse, params=ZERO)
    assert result.search["from_zero"] and result.search["floor_share"] > 0.5
    assert result.search["disparities"] == [0.0, 2.0 * c_max(scene.d_max)]
    assert result.theta_bg[5] == pytest.approx(0.0, abs=0.4)
    assert abs(result.theta_bg[3]) < 0.01
    s = score(result.disparity, result.occlusion, scene)
    assert s["occ_f1"] >= 0.9 and s["bad4"] <= 2.0
    assert result.disparity.min() >= 0.0
    # the left-view maps are in the user's columns: the foreground's edges on each row
    # within a pixel of the truth on average
    rows = scene.fg_left.any(axis=1) & result.foreground.any(axis=1)
    first = lambda m: np.argmax(m[rows], axis=1)
    last = lambda m: m.shape[1] - 1 - np.argmax(m[rows, ::-1], axis=1)
    assert abs(np.mean(first(result.foreground) - first(scene.fg_left))) < 0.6
    assert abs(np.mean(last(result.foreground) - last(scene.fg_left))) < 0.6


def _zero_background():
    return make_scene(None, seed=2, width=160, height=120, d_fg=10.0, d_bg=0.0,
                      ellipse=(82.0, 60.0, 36.0, 30.0), noise=0.01)


@pytest.mark.parametrize("refine", [False, True])
@pytest.mark.parametrize("which", ["easy", "zero background"])
def test_a_cyclopean_start_is_read_in_the_user_frame(ti_arch, which, refine):
    # the same ellipse given in the left view and, moved by half the foreground's
    # disparity, in the cyclopean frame starts the same region, whether the grid starts at
    # 2 px (easy: the background at 8 px) or at 0 px (the left view moved); read as the
    # ellipse itself, or as the box around it (Params.refine_ellipse)
    from lss_kernels import Solver
    scene = make_scene("easy") if which == "easy" else _zero_background()
    half = 12.0 if which == "easy" else 5.0
    cx, cy, rx, ry = scene.init_ellipse
    solver = Solver(scene.left, scene.right, scene.d_max, (cx, cy, rx, ry),
                    params=ZERO.replace(refine_ellipse=refine))
    try:
        assert solver.search["from_zero"] == (which != "easy")
        from_left = solver.initial_mask.copy()
        left_view = solver.initial_left.copy()
        info = solver.init_info
        solver.reset(scene.left, scene.right, scene.d_max, (cx - half, cy, rx, ry),
                     init_frame="cyclopean")
        from_cyclopean = solver.initial_mask.copy()
    finally:
        solver.close()
    assert (from_left != from_cyclopean).sum() <= 0.02 * from_left.sum()
    y, x = np.mgrid[0:scene.left.shape[0], 0:scene.left.shape[1]]
    given = ((x - cx) / rx) ** 2 + ((y - cy) / ry) ** 2 <= 1.0
    if not refine:      # the initial region reported in the left view is the ellipse given
        assert (left_view != given).sum() <= 0.01 * given.sum()
        return
    # the object under the centre, in the user's left view, cut to the ellipse's box
    assert info["region"]["from"] == "the region under the box's centre, cut to the box"
    x0, y0, x1, y1 = info["region"]["box"]
    assert abs(x0 - (cx - rx)) < 1e-3 and abs(y1 - (cy + ry)) < 1e-3
    fg, in_box = scene.fg_left, (x >= x0 - 1) & (x < x1 + 1) & (y >= y0) & (y < y1)
    assert not (left_view & ~in_box).any()
    assert (left_view & fg).sum() >= 0.95 * (fg & in_box).sum()   # this ellipse is small:
    assert (left_view & fg).sum() >= 1.2 * (given & fg).sum()     # its box holds more


def test_a_cyclopean_ellipse_over_the_background_is_moved_by_its_objects_shift(ti_arch):
    # a tall ellipse over the easy object's right edge lies mostly on the background (its
    # median consensus: 4.6 cyclopean px; the object's 12): read as its box, it is moved by
    # the object's shift, found under its centre (moved by the ellipse's own, the box lay
    # 7 px left and the region differed in 26 % of its pixels)
    from lss_kernels import Solver
    scene = make_scene("easy")
    cx, cy, rx, ry = 90.0, 48.0, 25.0, 48.0
    solver = Solver(scene.left, scene.right, scene.d_max, (cx, cy, rx, ry),
                    params=Params(max_iterations=1))
    try:
        from_left, box_left = solver.initial_left.copy(), solver.init_info["region"]["box"]
        solver.reset(scene.left, scene.right, scene.d_max, (cx - 12.0, cy, rx, ry),
                     init_frame="cyclopean")
        from_cyclopean, box = solver.initial_left.copy(), solver.init_info["region"]["box"]
    finally:
        solver.close()
    assert box_left[0] == cx - rx and abs(box[0] - box_left[0]) < 0.5
    assert (from_left != from_cyclopean).sum() <= 0.01 * from_left.sum()


def test_the_cli_says_where_the_search_started(tmp_path):
    import json
    import subprocess
    import sys
    from lss_kernels import io
    scene = _zero_background()
    for name, image in (("l.png", scene.left), ("r.png", scene.right)):
        io.write_png(tmp_path / name, np.round(np.clip(image, 0, 1) * 255).astype(np.uint8))
    out = tmp_path / "out"
    cx, cy, rx, ry = scene.init_ellipse
    proc = subprocess.run([sys.executable, "-m", "lss_kernels.apps.cli", "solve",
                           str(tmp_path / "l.png"), str(tmp_path / "r.png"), "--dmax",
                           str(scene.d_max), "--init", f"ellipse:{cx},{cy},{rx},{ry}",
                           "--max-iterations", "20", "--arch", "cpu", "--out", str(out)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert "disparities searched from 0 px" in proc.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["search"]["from_zero"] is True
    assert summary["search"]["disparities"] == [0.0, 2.0 * c_max(scene.d_max)]


def test_without_zero_floor_the_authors_grid_is_kept(ti_arch):
    # a 0 px background stays at the grid's floor, 2 px (and says so)
    from lss_kernels import Solver
    scene = _zero_background()
    solver = Solver(scene.left, scene.right, scene.d_max, scene.init_ellipse,
                    params=Params(zero_floor=False, max_iterations=1))
    try:
        assert solver.c_max == c_max(scene.d_max) == int(np.ceil(scene.d_max / 2))
        assert solver.search["floor_share"] > 0.5 and not solver.search["from_zero"]
        assert solver.search["disparities"] == [2.0, 2.0 * solver.c_max]
        assert solver.shift == 0
    finally:
        solver.close()
    with pytest.raises(ValueError, match="zero_floor"):
        Params(zero_floor="yes")


def test_a_pair_that_does_not_move_is_solved_as_without_the_option(ti_arch):
    # the option reaches no other pair: the same fields (the authors' plane count) and,
    # bit for bit, the same model
    from lss_kernels import Solver
    scene = make_scene("easy")
    outs = []
    for params in (Params(max_iterations=12), Params(zero_floor=False, max_iterations=12)):
        solver = Solver(scene.left, scene.right, scene.d_max, scene.init_ellipse, params=params)
        try:
            assert solver.c_max == c_max(scene.d_max) and not solver.search["from_zero"]
            outs.append(solver.run())
        finally:
            solver.close()
    np.testing.assert_array_equal(outs[0].phi, outs[1].phi)
    np.testing.assert_array_equal(outs[0].disparity, outs[1].disparity)


@pytest.mark.slow
def test_a_reset_solver_moves_between_the_grids_like_new_solvers(ti_arch):
    # from 0 px (one plane more) to the authors' grid and back, in one solver: each solve
    # as a new solver's
    from lss_kernels import Solver
    zero = _zero_background()
    easy = make_scene(None, seed=2, width=160, height=120, d_fg=10.0, d_bg=6.0,
                      ellipse=(82.0, 60.0, 36.0, 30.0), noise=0.01)
    assert c_max(zero.d_max) == c_max(easy.d_max)
    params = Params(max_iterations=8)
    fresh = []
    for scene in (zero, easy):
        solver = Solver(scene.left, scene.right, scene.d_max, scene.init_ellipse, params=params)
        try:
            fresh.append((solver.c_max, solver.run()))
        finally:
            solver.close()
    assert fresh[0][0] == c_max(zero.d_max) + 1 and fresh[1][0] == c_max(easy.d_max)
    solver = Solver(zero.left, zero.right, zero.d_max, zero.init_ellipse, params=params)
    try:
        for scene, (planes, want) in ((easy, fresh[1]), (zero, fresh[0])):
            solver.reset(scene.left, scene.right, scene.d_max, scene.init_ellipse)
            assert solver.c_max == planes
            got = solver.run()
            np.testing.assert_array_equal(got.phi, want.phi)
            np.testing.assert_array_equal(got.disparity, want.disparity)
    finally:
        solver.close()


def test_a_left_view_start_moves_by_half_the_foreground_disparity():
    # lss_kernels.model.start: x_left = x_c + c, with c the median consensus over the region
    from lss_kernels.model.start import cyclopean_start
    H, W = 40, 60
    mean = np.full((H, W), 2.0)
    mean[:, 20:40] = 6.0                    # the object's rows and columns: c = 6
    precision = np.ones((H, W))
    precision[:, 20:23] = 0.0               # no consensus there: not read
    mask = np.zeros((H, W), bool)
    mask[10:30, 22:38] = True
    cyclopean, left = cyclopean_start(mask, "left", mean, precision)
    np.testing.assert_array_equal(left, mask)
    np.testing.assert_array_equal(cyclopean[:, 16:32], mask[:, 22:38])
    assert cyclopean.sum() == mask.sum()
    back, moved = cyclopean_start(cyclopean, "cyclopean", mean, precision)
    np.testing.assert_array_equal(back, cyclopean)
    # read at columns 16-31: four columns at 2, nine at 6 (20-22 have no consensus)
    np.testing.assert_array_equal(moved, mask)
    ellipse, _ = cyclopean_start((30.0, 20.0, 5.0, 5.0), "left", mean, precision)
    y, x = np.mgrid[0:H, 0:W]
    np.testing.assert_array_equal(ellipse, ((x - 24.0) / 5) ** 2 + ((y - 20.0) / 5) ** 2 <= 1)
