"""The right view's photometric correction (lss_kernels.checks.photometry): the model fitted at the
matches against rendered pairs with a known gain, vignetting and offset; the pairs it must
leave alone; the solver's use of it."""
import numpy as np
import pytest

from lss_kernels.checks.photometry import MIN_DIFFERENCE, _radius2, equalise, fit
from lss_kernels.scenes import make_scene


@pytest.fixture(scope="module")
def scene():
    return make_scene("easy", seed=1, width=192, height=144, d_fg=20.0, d_bg=6.0)


def _changed(right, gain, vignetting, offset):
    """``right`` as a camera with this photometry would see it: (g0 + g2 r^2) R + o."""
    H, W = right.shape[:2]
    y, x = np.mgrid[0:H, 0:W]
    g = gain + vignetting * _radius2(x, y, W, H)
    return np.clip(g[..., None] * right + offset, 0.0, 1.0).astype(np.float32)


@pytest.mark.parametrize("gain, vignetting, offset", [
    (1.0, 0.0, 0.08),          # 20 grey levels brighter
    (1.15, 0.0, 0.0),          # a longer exposure
    (1.0, -0.4, 0.0),          # 40 % darker in the corners
    (0.9, -0.2, 0.05),
])
def test_a_known_photometry_is_recovered_and_undone(scene, gain, vignetting, offset):
    right = _changed(scene.right, gain, vignetting, offset)
    facts = fit(scene.left, right, scene.d_max)
    assert facts["correct"], facts
    assert facts["gain"] == pytest.approx(gain, abs=0.03)
    assert facts["vignetting"] == pytest.approx(vignetting, abs=0.05)
    assert facts["offset"] == pytest.approx(offset, abs=0.015)
    assert facts["difference"] >= MIN_DIFFERENCE and facts["residual"] < 0.01
    corrected, same = equalise(scene.left, right, scene.d_max)
    assert same == facts
    before = np.median(np.abs(right - scene.right))
    after = np.median(np.abs(corrected - scene.right))
    assert after < 0.01 < before and corrected.dtype == np.float32


def test_a_pair_that_matches_is_left_alone(scene):
    facts = fit(scene.left, scene.right, scene.d_max)
    assert not facts["correct"] and facts["difference"] < 0.005
    assert "differ by less" in facts["why"]
    corrected, _ = equalise(scene.left, scene.right, scene.d_max)
    assert corrected is scene.right


def test_a_difference_the_model_cannot_explain_is_left_alone(scene):
    """A right view in negative, or of pure noise, has no gain and offset that make it the
    left one: the pair is not corrected."""
    facts = fit(scene.left, 1.0 - scene.right, scene.d_max)
    assert not facts["correct"] and ("out of range" in facts["why"]
                                     or "unexplained" in facts["why"])
    noise = np.random.default_rng(0).random(scene.right.shape).astype(np.float32)
    assert not fit(scene.left, noise, scene.d_max)["correct"]


def test_too_little_texture_gives_no_verdict():
    flat = np.full((48, 64, 3), 0.5, np.float32)
    facts = fit(flat, flat + 0.1, 10)
    assert not facts["correct"] and facts["matches"] == 0 and "textured" in facts["why"]
    facts = fit(flat[:, :12], flat[:, :12], 10)
    assert not facts["correct"] and "too narrow" in facts["why"]


@pytest.mark.slow
def test_the_solver_corrects_the_right_view_and_says_so(scene, ti_arch):
    from lss_kernels import Params, Solver
    right = _changed(scene.right, 1.0, 0.0, 0.08)
    solver = Solver(scene.left, right, scene.d_max, tuple(scene.init_ellipse),
                    params=Params(max_iterations=1))
    try:
        assert solver.photometry["correct"]
        loaded = solver.extent.image(solver.right)
        assert np.median(np.abs(loaded - scene.right)) < 0.01
        assert solver.result().photometry == solver.photometry
        solver.reset(scene.left, right, scene.d_max, tuple(scene.init_ellipse))
        assert solver.photometry["correct"]
    finally:
        solver.close()
    solver = Solver(scene.left, right, scene.d_max, tuple(scene.init_ellipse),
                    params=Params(max_iterations=1, photometric=False))
    try:
        assert not solver.photometry["correct"]
        assert np.array_equal(solver.extent.image(solver.right), right)
    finally:
        solver.close()


@pytest.mark.slow
def test_a_vignetted_right_view_of_a_weak_foreground_is_solved(ti_arch):
    """Seed 1's medium stress scene ``weak_fg_grey`` (12 grey levels on the foreground) with
    the right view 40 % darker in the corners: without the correction the foreground loses
    its matches (F1 0.66 measured); corrected, it is solved as the undegraded pair (0.99)."""
    from lss_kernels import solve, stress
    from lss_kernels.metrics import score
    name, keywords = next(s for s in stress.stress_specs(seed=1, size="medium")
                          if s[0] == "weak_fg_grey")
    keywords.pop("meta")
    scene = make_scene(None, **keywords)
    right = np.round(_changed(scene.right, 1.0, -0.4, 0.0) * 255) / 255
    result = solve(scene.left, right, scene.d_max, scene.init_ellipse)
    assert result.photometry["correct"]
    assert result.photometry["vignetting"] == pytest.approx(-0.4, abs=0.05)
    assert score(result.disparity, result.occlusion, scene)["occ_f1"] >= 0.95
