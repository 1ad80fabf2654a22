"""The foreground's tooth on a pair with stripes on both layers (checks/teeth.py): a model
whose object sits whole periods too near the background, its outline moved with it, as the
solve leaves it on ``periodic_same_*`` (issue 54), is moved back by the warp of the left
image onto the right one."""
from types import SimpleNamespace

import numpy as np
import pytest

from lss_kernels import Params
from lss_kernels.checks import teeth
from lss_kernels.checks.pair import CheckedPair
from lss_kernels.checks.recovery import with_recovery
from lss_kernels.metrics import score
from lss_kernels.scenes import make_scene

D_FG, D_BG, PERIOD = 20.0, 6.0, 5.3


@pytest.fixture(scope="module")
def scene():
    stripes = {"kind": "stripes", "period": PERIOD}
    return make_scene(None, seed=3, width=160, height=120, d_fg=D_FG, d_bg=D_BG,
                      ellipse=(84.0, 60.0, 34.0, 38.0), texture_fg=stripes,
                      texture_bg=stripes)


def wrong_tooth(scene, periods=2, shift=-7, background=0):
    """A Result-like model of ``scene``: the true outline moved ``shift`` columns, the
    foreground's surface ``periods`` periods too small, the background ``background``
    periods too large."""
    fg = np.roll(scene.fg_left, shift, axis=1)
    surface = np.where(fg, D_FG - periods * PERIOD, D_BG + background * PERIOD)
    surface = surface.astype(np.float32)
    from lss_kernels.model.layers import occlusion_by_layers
    occlusion = occlusion_by_layers(surface, fg.astype(np.int32))
    return SimpleNamespace(foreground=fg, surface=surface, disparity=surface.copy(),
                           occlusion=occlusion, confidence=np.ones(fg.shape, np.float32),
                           phi=np.where(fg, 1.0, -1.0).astype(np.float32), layers=None,
                           theta_fg=np.array([0, 0, 0, 0, 0, D_FG - periods * PERIOD]),
                           theta_bg=np.array([0, 0, 0, 0, 0, D_BG + background * PERIOD]),
                           recovery={})


def test_the_period_of_the_stripes_is_read_inside_a_mask(scene):
    assert teeth.row_period(scene.left, scene.fg_left) == pytest.approx(PERIOD, abs=0.15)
    rng = np.random.default_rng(0)
    assert teeth.row_period(rng.random((60, 80, 3)), np.ones((60, 80), bool)) is None


def test_the_true_model_explains_the_right_image_better_than_a_tooth_off(scene):
    right = teeth.upsampled(scene.right.astype(np.float64))
    true = teeth.warp_cost(scene.left, right, scene.fg_left, scene.disp_left, teeth.UPSAMPLE)[0]
    for k in (-2, -1, 1):
        off = np.where(scene.fg_left, scene.disp_left + k * PERIOD, scene.disp_left)
        wrong = teeth.warp_cost(scene.left, right, scene.fg_left, off, teeth.UPSAMPLE)[0]
        assert wrong > 2 * true


@pytest.mark.parametrize("periods, shift", [(2, -7), (1, -5), (-1, 3)])
def test_a_periodic_solve_a_tooth_off_is_moved_to_the_true_one(ti_arch, scene, periods, shift):
    pair = CheckedPair(scene.left, scene.right, scene.d_max, tuple(scene.init_ellipse), "left",
                       Params())
    before = wrong_tooth(scene, periods, shift)
    f1_before = score(before.surface, before.occlusion, scene)["occ_f1"]
    result, _ = with_recovery(lambda p: (wrong_tooth(scene, periods, shift), None), Params(),
                              pair.d_max, pair)
    inside = scene.fg_left & result.foreground
    assert np.abs(result.surface[inside] - D_FG).max() < 1.0
    assert (result.foreground == scene.fg_left).mean() > 0.98
    assert score(result.surface, result.occlusion, scene)["occ_f1"] > max(0.95, f1_before + 0.1)
    assert result.recovery["tooth"]["offset"] == pytest.approx(periods * PERIOD, abs=0.5)
    assert result.theta_fg[5] == pytest.approx(D_FG, abs=0.5)


def test_a_background_left_in_front_of_the_moved_object_goes_to_the_nearest_tooth_behind(
        ti_arch, scene):
    # the solve put the background three periods too near (in front of the true object):
    # the pair cannot say which of its teeth is true (the images are the same), the nearest
    # one behind the object is taken, and the model is sound
    pair = CheckedPair(scene.left, scene.right, scene.d_max, tuple(scene.init_ellipse), "left",
                       Params())
    result, _ = with_recovery(lambda p: (wrong_tooth(scene, 2, -7, background=3), None),
                              Params(), pair.d_max, pair)
    assert result.recovery["collapse"] is None
    assert np.median(result.surface[~result.foreground]) == pytest.approx(D_BG + 2 * PERIOD,
                                                                          abs=0.3)
    tooth = result.recovery["tooth"]
    assert tooth["offset"] == pytest.approx(2 * PERIOD, abs=0.5)
    assert tooth["background_offset"] == pytest.approx(-PERIOD, abs=0.3)
