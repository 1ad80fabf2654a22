"""Property tests (hypothesis) and degenerate scenes.

Most examples exercise the cheap boundary (``check_init``, ``parse_init``, ``Params``, image
reading, PFM round trips, the metrics); a few run the solver on small random scenes.  Every
solver run uses the same image size (48x64) and the same ``d_max`` (14, so ``c_max`` = 7):
each new size or ``c_max`` costs a Taichi compilation.
"""
import json
import math

import imageio.v3 as iio
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

from lss_kernels import Params, solve
from lss_kernels.apps.cli import main
from lss_kernels.io import read_image, read_pfm, write_pfm
from lss_kernels.metrics import score_arrays
from lss_kernels.scenes import make_scene
from lss_kernels.checks.validate import MIN_RADIUS, check_init, parse_init

H, W = 48, 64
D_MAX = 14.0          # the tiny preset's d_max: one c_max for every solver run here
FAST = settings(deadline=None, max_examples=60,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])

finite = st.floats(-200, 200, allow_nan=False)
anything = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-5, 5),
                     st.booleans(), st.none(), st.text(max_size=3))


# ------------------------------------------------------------------------------ boundary
@FAST
@given(cx=finite, cy=finite, rx=st.floats(-20, 80), ry=st.floats(-20, 80))
@example(cx=63.0, cy=0.0, rx=1.4e-110, ry=5.0)     # a degenerate radius on the last column
@example(cx=64.0, cy=0.0, rx=1.0, ry=1.0)          # the last column on the ellipse's rim
@example(cx=-1.0, cy=-1.0, rx=1.0, ry=1.0)         # the corner pixel outside the rim
def test_check_init_accepts_exactly_the_ellipses_that_cover_a_pixel(cx, cy, rx, ry):
    y, x = np.mgrid[0:H, 0:W]
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        covers = rx >= MIN_RADIUS and ry >= MIN_RADIUS and bool(
            (((x - cx) / rx) ** 2 + ((y - cy) / ry) ** 2 <= 1.0).any())
    try:
        out = check_init((cx, cy, rx, ry), (H, W))
    except ValueError as exc:
        assert not covers
        assert str(exc).startswith("init: ") and "\n" not in str(exc)
    else:
        assert covers and out == (cx, cy, rx, ry)


@FAST
@given(st.lists(anything, max_size=6))
def test_check_init_never_leaks_a_raw_error(values):
    try:
        check_init(values, (H, W))
    except ValueError as exc:
        assert str(exc).startswith("init: ") and "\n" not in str(exc)


@FAST
@given(mask=st.lists(st.booleans(), min_size=H * W, max_size=H * W))
def test_check_init_masks(mask):
    m = np.array(mask).reshape(H, W)
    if m.any() and not m.all():
        out = check_init(m.astype(np.uint8), (H, W))
        assert out.dtype == bool and np.array_equal(out, m)
    else:
        with pytest.raises(ValueError, match=r"^init: the mask (is empty|covers the whole)"):
            check_init(m, (H, W))


@FAST
@given(st.lists(st.floats(allow_nan=True, allow_infinity=True, allow_subnormal=False),
                min_size=4, max_size=4))
def test_parse_init_round_trips_ellipses(values):
    # (no subnormals: Taichi's runtime flushes denormals to zero in this process)
    text = "ellipse:" + ",".join(repr(v) for v in values)
    if all(math.isfinite(v) for v in values):
        assert parse_init(text) == tuple(values)
    else:
        with pytest.raises(ValueError, match=r"^--init: expected 4 finite numbers"):
            parse_init(text)


@FAST
@given(st.text(max_size=20))
def test_parse_init_fails_in_one_line(text):
    assume(not text.lower().endswith(".png") and not text.startswith("mask:"))
    try:
        values = parse_init(text)
    except ValueError as exc:
        assert str(exc).startswith("--init: ") and "\n" not in str(exc)
    else:
        assert text.startswith("ellipse:") and len(values) == 4


@FAST
@given(dt=anything, mu=anything, beta=anything, max_iterations=anything)
def test_params_accept_exactly_the_valid_values(dt, mu, beta, max_iterations):
    def num(v):
        return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)

    valid = (num(dt) and 0 < dt <= 10 and num(mu) and mu >= 0 and num(beta) and beta >= 0
             and isinstance(max_iterations, int) and not isinstance(max_iterations, bool)
             and max_iterations >= 1)
    try:
        p = Params(dt=dt, mu=mu, beta=beta, max_iterations=max_iterations)
    except ValueError as exc:
        assert not valid
        assert str(exc).startswith("params.") and "\n" not in str(exc)
    else:
        assert valid and p.dt == dt


@FAST
@given(shape=st.sampled_from([(H, W), (H, W, 1), (H, W, 3), (H, W, 4)]),
       dtype=st.sampled_from([np.uint8, np.uint16, np.float32, np.float64, bool]),
       seed=st.integers(0, 2 ** 16))
def test_read_image_gives_rgb_in_the_unit_range(shape, dtype, seed):
    rng = np.random.default_rng(seed)
    raw = rng.random(shape)
    if dtype in (np.uint8, np.uint16):
        raw = raw * np.iinfo(dtype).max
    elif dtype is bool:
        raw = raw > 0.5
    img = read_image(raw.astype(dtype), "left")
    assert img.shape == (H, W, 3) and img.dtype == np.float32
    assert np.isfinite(img).all() and img.min() >= 0.0 and img.max() <= 1.0


@settings(deadline=None, max_examples=40,
          suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])
@given(seed=st.integers(0, 2 ** 16), holes=st.booleans())
def test_pfm_round_trip_is_exact(tmp_path, seed, holes):
    rng = np.random.default_rng(seed)
    d = (rng.standard_normal((H, W)) * 30).astype(np.float32)
    if holes:
        d[rng.random((H, W)) < 0.1] = np.inf
    f = write_pfm(tmp_path / "d.pfm", d)
    np.testing.assert_array_equal(read_pfm(f), d)


@FAST
@given(seed=st.integers(0, 2 ** 16), nonfinite=st.booleans())
def test_scores_stay_in_range(seed, nonfinite):
    rng = np.random.default_rng(seed)
    disp = (rng.random((H, W)) * D_MAX).astype(np.float32)
    if nonfinite:
        disp[rng.random((H, W)) < 0.05] = np.nan
    truth = (rng.random((H, W)) * D_MAX).astype(np.float32)
    occ_true, roi_fg = rng.random((H, W)) < 0.1, rng.random((H, W)) < 0.3
    s = score_arrays(disp, rng.random((H, W)) < 0.1, truth, occ_true, roi_fg, ~roi_fg)
    assert 0.0 <= s["occ_f1"] <= 1.0 and 0.0 <= s["bad4"] <= 100.0


# ------------------------------------------------------------------------------ solver
def _check_result(r, d_max=D_MAX, bound_by_d_max=True):
    for name in ("disparity", "phi", "consensus_mean", "consensus_sigma"):
        a = getattr(r, name)
        assert a.shape == (H, W) and np.isfinite(a).all(), name
    assert np.isfinite(r.theta_fg).all() and np.isfinite(r.theta_bg).all()
    assert r.occlusion.dtype == bool and r.foreground.dtype == bool
    assert not (r.occlusion & r.foreground).any()
    assert (r.disparity >= 0).all()
    if bound_by_d_max:
        assert r.disparity.max() <= d_max, f"disparity up to {r.disparity.max()} > d_max"
    assert (r.consensus_sigma > 0).all() and (r.consensus_sigma <= d_max).all()
    assert r.iterations == len(r.history) >= 1 and r.stop_reason


@pytest.mark.slow
@settings(deadline=None, max_examples=4, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])
@given(seed=st.integers(0, 1000), d_fg=st.floats(6.0, 12.0), noise=st.floats(0.0, 0.05),
       shift=st.tuples(st.floats(-6, 6), st.floats(-4, 4)), scale=st.floats(0.4, 1.3),
       iterations=st.integers(5, 12))
def test_solver_on_random_small_scenes(ti_arch, seed, d_fg, noise, shift, scale, iterations):
    scene = make_scene("tiny", seed=seed, d_fg=d_fg, noise=noise, init_shift=shift,
                       init_scale=scale)
    assert scene.left.shape[:2] == (H, W) and scene.d_max <= D_MAX
    r = solve(scene.left, scene.right, D_MAX, scene.init_ellipse,
              params=Params(max_iterations=iterations))
    # The disparity is 2 Theta . U rendered in the left view; nothing bounds it by d_max
    # (see test_disparity_can_exceed_d_max), so only >= 0 and finiteness are asserted here.
    _check_result(r, bound_by_d_max=False)
    assert r.iterations <= iterations


# ------------------------------------------------------------------------------ degenerate
@pytest.mark.slow
def test_textureless_images_finish_with_a_reason(ti_arch, tmp_path, capsys):
    """Through the CLI: the reason is in summary.json."""
    gray = np.full((H, W, 3), 128, np.uint8)
    iio.imwrite(tmp_path / "l.png", gray)
    iio.imwrite(tmp_path / "r.png", gray)
    out = tmp_path / "out"
    code = main(["solve", str(tmp_path / "l.png"), str(tmp_path / "r.png"), "--dmax",
                 str(D_MAX), "--init", "ellipse:32,24,11,10", "--out", str(out), "--arch",
                 ti_arch, "--max-iterations", "15", "--quiet"])
    assert code == 0, capsys.readouterr().err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stop_reason"].startswith(("foreground vanished at iteration",
                                              "foreground filled the image at iteration",
                                              "reached the iteration cap"))
    assert np.isfinite(read_pfm(out / "disparity.pfm")).all()


@pytest.mark.slow
def test_identical_images_finish_with_a_reason(ti_arch):
    scene = make_scene("tiny", seed=4)
    r = solve(scene.left, scene.left, D_MAX, scene.init_ellipse,
              params=Params(max_iterations=15))
    _check_result(r)
    # Zero disparity is outside the search range (1..c_max): no layer is in front.
    assert r.stop_reason.startswith("foreground vanished at iteration")


@pytest.mark.slow
def test_d_max_below_the_true_disparity(ti_arch):
    scene = make_scene("tiny", seed=5, d_fg=20.0, d_bg=4.0)
    r = solve(scene.left, scene.right, D_MAX, scene.init_ellipse,
              params=Params(max_iterations=15))
    _check_result(r)
    assert r.stop_reason.startswith(("foreground vanished at iteration",
                                     "reached the iteration cap"))


@pytest.mark.slow
def test_foreground_that_fills_the_image(ti_arch):
    # the ellipse as given (refine_ellipse off): read as its box, it would start from the
    # object under its centre instead of the whole image
    scene = make_scene("tiny", seed=6)
    r = solve(scene.left, scene.right, D_MAX, (32.0, 24.0, 60.0, 50.0),
              params=Params(max_iterations=15, refine_ellipse=False))
    _check_result(r, bound_by_d_max=False)
    assert r.stop_reason == "foreground filled the image at iteration 1"


@pytest.mark.slow
def test_disparity_stays_within_the_search_range(ti_arch):
    """An initial ellipse in the background corner of the tiny scene: the 'foreground' takes
    the background's 4 px plane and Theta_bg becomes a steep quadratic; D and the left-view
    disparity are clamped to the searched range [0, d_max]."""
    scene = make_scene("tiny")
    r = solve(scene.left, scene.right, D_MAX, (8.0, 8.0, 5.0, 5.0),
              params=Params(max_iterations=15))
    _check_result(r, bound_by_d_max=True)
