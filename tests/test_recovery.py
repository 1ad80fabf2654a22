"""Collapse of a model recognised without ground truth, and the second solve with AD-Census
and distinctness-weighted messages."""
import warnings
from types import SimpleNamespace

import numpy as np
import pytest

from lss_kernels import Params
from lss_kernels.checks import periodicity, recovery
from lss_kernels.checks.pair import CheckedPair
from lss_kernels.checks.recovery import collapse, model_health, with_recovery

H, W = 20, 30
D_MAX = 64.0


def model(jump=10.0, slope=0.0, region=(slice(5, 15), slice(10, 20)), matches_bg=0.0,
          matches_fg=0.0):
    """A Result-like model: phi > 0 on ``region``; Theta_2 = 20, Theta_1 = 20 + jump +
    slope * x (left-view disparity over {x^2, xy, y^2, x, y, 1}); the refined disparity
    lies ``matches_fg`` from the surface on the foreground and ``matches_bg`` on the background,
    except on the occluded strip (two columns left of the region's left edge), where it is 0."""
    phi = -np.ones((H, W))
    if region is not None:
        phi[region] = 1.0
    foreground = phi > 0
    x = np.arange(W, dtype=np.float64)[None, :].repeat(H, 0)
    surface = np.where(foreground, 20.0 + jump + slope * x, 20.0)
    occlusion = np.zeros((H, W), bool)
    left_edge = foreground & ~np.roll(foreground, 1, axis=1)
    for shift in (1, 2):
        occlusion |= np.roll(left_edge, -shift, axis=1) & ~foreground
    disparity = surface + np.where(foreground, matches_fg, matches_bg)
    disparity[occlusion] = 0.0
    return SimpleNamespace(phi=phi, theta_fg=np.array([0, 0, 0, slope, 0, 20.0 + jump]),
                           theta_bg=np.array([0, 0, 0, 0, 0, 20.0]), foreground=foreground,
                           surface=surface, disparity=disparity, occlusion=occlusion,
                           recovery={})


def test_a_sound_model_has_a_jump_in_front():
    health = model_health(model(jump=10.0), D_MAX)
    assert health == {"area": 100 / (H * W), "jump": pytest.approx(10.0), "crossing": 0.0,
                      "out_of_range": 0.0, "offset_fg": 0.0, "offset_bg": 0.0}
    assert collapse(health) is None


def test_each_kind_of_collapse_is_named():
    assert collapse(model_health(model(region=None), D_MAX)) == "the foreground vanished"
    full = model(region=(slice(None), slice(None)))
    assert collapse(model_health(full, D_MAX)) == "the foreground filled the image"
    assert "mean jump 0.30 px" in collapse(model_health(model(jump=0.3), D_MAX))
    # Theta_1 - Theta_2 = x - 10: behind on columns 0..5, 15..19 px in front on 25..29
    split = model(jump=-10.0, slope=1.0, region=(slice(5, 15), np.r_[0:6, 25:30]))
    health = model_health(split, D_MAX)
    assert health["jump"] == pytest.approx(40 / 11) and health["crossing"] == pytest.approx(6 / 11)
    assert "behind the background on 55%" in collapse(health)


def test_a_surface_far_from_its_own_matches_is_a_collapse():
    """The background's refined matches lie 12 px below Theta_2 (a background pulled
    towards the foreground): a collapse, named with the offset; 3 px is within bounds."""
    health = model_health(model(matches_bg=-12.0), D_MAX)
    assert health["offset_bg"] == -12.0 and health["offset_fg"] == 0.0
    assert "background surface lies -12.0 px from its own matches" in collapse(health)
    assert collapse(model_health(model(matches_bg=3.0), D_MAX)) is None
    assert model_health(model(matches_bg=3.0), D_MAX)["offset_bg"] == 3.0


def test_the_foreground_offset_is_reported_but_not_judged():
    """A striped foreground's refined matches may lie a period off its surface."""
    health = model_health(model(matches_fg=7.0), D_MAX)
    assert health["offset_fg"] == 7.0 and health["offset_bg"] == 0.0
    assert collapse(health) is None


def test_a_foreground_surface_bent_out_of_the_searched_range_is_a_collapse():
    # Theta_1 = 30 + 3 (x - 10) on columns 10..19: above d_max = 64 from x = 22 on, never
    # on the object; the same slope over columns 10..29 leaves the range on columns 22..29
    inside = model(jump=10.0, slope=3.0)
    inside.theta_fg[-1] -= 30.0
    assert collapse(model_health(inside, D_MAX)) is None
    wide = model(jump=10.0, slope=3.0, region=(slice(5, 15), slice(10, 30)))
    wide.theta_fg[-1] -= 30.0
    health = model_health(wide, D_MAX)
    assert health["out_of_range"] == pytest.approx(8 / 20)
    assert "leaves [0, d_max] on 40%" in collapse(health)
    assert collapse(model_health(wide, 100.0)) is None


def runs(*models):
    """A run function that returns the given models in turn and records the params."""
    calls = []

    def run(params):
        calls.append(params)
        return models[len(calls) - 1], len(calls)
    return run, calls


def test_a_collapsed_model_is_solved_again_with_census_and_the_sound_one_kept():
    run, calls = runs(model(jump=0.1), model(jump=12.0))
    with warnings.catch_warnings():
        warnings.simplefilter("error", recovery.CollapsedModelWarning)   # a sound model kept
        result, extra = with_recovery(run, Params(), D_MAX)
    assert calls == [Params(), Params().replace(**recovery.RECOVERY)]
    assert extra == 2 and result.recovery["kept"] == "retry"
    assert result.recovery["retry_health"]["jump"] == pytest.approx(12.0)
    assert "mean jump 0.10" in result.recovery["collapse"]


def test_no_params_means_the_defaults():
    run, calls = runs(model(jump=0.0), model(jump=12.0))
    result, _ = with_recovery(run, None, D_MAX)
    assert calls == [Params(), Params().replace(**recovery.RECOVERY)]
    assert result.recovery["kept"] == "retry"


def test_a_retry_that_finds_no_start_keeps_the_first():
    from lss_kernels.model.init import InitError
    first = model(jump=0.0)
    calls = []

    def run(params):
        calls.append(params)
        if len(calls) == 2:
            raise InitError("init auto: no foreground found")
        return first, 1
    with pytest.warns(recovery.CollapsedModelWarning, match=r"^no sound model: the surfaces "
                      r"coincide.*; so did the solve again with matching_cost=ad_census, .*"
                      r"\(init auto: no foreground found\); the output is no two-layer"):
        result, extra = with_recovery(run, Params(), D_MAX)
    assert result is first and result.recovery["kept"] == "first"
    assert "no foreground found" in result.recovery["retry_error"]


def test_a_sound_retry_is_kept_even_with_a_smaller_jump():
    # a first model bent out of range (jump 40 on average) against a sound one (jump 12)
    first = model(jump=10.0, slope=3.0, region=(slice(5, 15), slice(10, 30)))
    first.theta_fg[-1] -= 30.0
    run, calls = runs(first, model(jump=12.0))
    result, _ = with_recovery(run, Params(), D_MAX)
    assert len(calls) == 2 and result.recovery["kept"] == "retry"
    assert result.recovery["health"]["jump"] > result.recovery["retry_health"]["jump"]


def test_a_retry_that_is_no_sounder_is_dropped():
    first = model(jump=0.5)
    run, calls = runs(first, model(jump=0.2))
    with pytest.warns(recovery.CollapsedModelWarning, match=r"mean jump 0.50.*so did the "
                      r"solve again .*mean jump 0.20"):
        result, extra = with_recovery(run, Params(), D_MAX)
    assert result is first and extra == 1 and result.recovery["kept"] == "first"
    assert result.recovery["retry_collapse"] is not None


@pytest.mark.parametrize("params, first_jump", [
    (Params(), 10.0),                              # a sound model
    (Params(recover=False), 0.0),                  # collapsed, recovery switched off
    (Params().replace(**recovery.RECOVERY), 0.0),  # collapsed, the recovery's already
])
def test_no_second_solve_without_need_or_leave(params, first_jump):
    run, calls = runs(model(jump=first_jump), model(jump=12.0))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result, _ = with_recovery(run, params, D_MAX)
    assert len(calls) == 1 and result.recovery["retried"] is False
    assert (result.recovery["collapse"] is None) == (first_jump > 1.0)
    # a collapsed model kept, also with the recovery off, says so (without a retry clause)
    said = [str(w.message) for w in caught if w.category is recovery.CollapsedModelWarning]
    assert len(said) == (first_jump <= 1.0)
    assert all(m.startswith("no sound model: the surfaces coincide") and "so did" not in m
               for m in said)


def checked(left):
    """``left`` twice, as :func:`lss_kernels.solve` checks a pair (started automatically)."""
    return CheckedPair(left, left, D_MAX, "auto", "left", Params())


def stripes(period, shape=(64, 160), phase=0.0):
    """Vertical sinusoidal stripes of ``period`` pixels, grey in [0, 1]."""
    x = np.arange(shape[1])
    return np.broadcast_to(0.5 + 0.4 * np.sin(2 * np.pi * (x + phase) / period), shape).copy()


def autocorrelation_score(tile, lags):
    """The score of one tile written out: the correlation of the gradient with itself
    shifted by each lag, and half the largest rise from a dip to a later local peak."""
    gx = np.diff(tile, axis=1)
    width = gx.shape[1] - lags
    base = gx[:, :width]
    rho = [np.sum(base * gx[:, t:t + width]) /
           np.sqrt(np.sum(base ** 2) * np.sum(gx[:, t:t + width] ** 2)) for t in range(1, lags + 1)]
    best = 0.0
    for i in range(1, lags - 1):
        if rho[i] >= rho[i - 1] and rho[i] >= rho[i + 1]:
            best = max(best, (rho[i] - min(rho[:i])) / 2)
    return min(best, 1.0)


def test_periodicity_of_a_tile_follows_its_written_out_definition():
    rng = np.random.default_rng(3)
    th, tw = periodicity.TILE
    tile = rng.random((th, tw + periodicity.MAX_PERIOD + 1)) + stripes(9, (th, tw + 33))
    score = periodicity.periodicity(tile)
    assert score.shape == (1, 1)
    assert score[0, 0] == pytest.approx(autocorrelation_score(tile, periodicity.MAX_PERIOD))


@pytest.mark.parametrize("period", [3, 6, 11, 24])
def test_stripes_are_periodic_and_noise_is_not(period):
    rng = np.random.default_rng(period)
    assert periodicity.periodic_fraction(stripes(period)) == 1.0
    # sampled at whole pixels, stripes of 3 dip to only cos(2 pi / 3) = -0.5 at lag 1
    assert periodicity.periodicity(stripes(period)).min() > (0.74 if period == 3 else 0.9)
    noise = rng.random((64, 160, 3))
    assert periodicity.periodicity(noise).max() < 0.4
    assert periodicity.periodic_fraction(noise) == 0.0


def test_smooth_flat_and_small_images_are_not_periodic():
    y, x = np.mgrid[0:64, 0:160]
    assert periodicity.periodic_fraction(np.sin(x / 40.0) + y / 64.0) == 0.0   # no dip and rise
    assert periodicity.periodic_fraction(np.full((64, 160), 0.5)) == 0.0       # no gradient
    assert periodicity.periodic_fraction(stripes(6, (10, 40))) == 0.0          # no whole tile


def test_the_periodic_fraction_counts_the_striped_tiles():
    rng = np.random.default_rng(0)
    image = rng.random((64, 160))
    image[:32] = stripes(7, (32, 160))            # 2 of 4 tile rows striped
    assert periodicity.periodic_fraction(image) == 0.5


def test_the_periodic_share_is_the_fraction_from_periodic_area_on_and_zero_below_it():
    rng = np.random.default_rng(1)
    image = rng.random((64 * 10, 160))
    image[:64] = stripes(7, (64, 160))            # 4 of 40 tile rows striped: 0.1
    assert periodicity.periodic_fraction(image) == pytest.approx(0.1)
    assert periodicity.periodic_share(image) == pytest.approx(0.1)
    image[16:64] = rng.random((48, 160))          # 1 of 40: below PERIODIC_AREA (0.05)
    assert periodicity.periodic_fraction(image) == pytest.approx(0.025)
    assert periodicity.periodic_share(image) == 0.0


def test_a_periodic_pair_is_solved_with_the_recovery_unrefined_first_and_the_defaults_second():
    run, calls = runs(model(jump=0.0), model(jump=12.0))
    result, _ = with_recovery(run, Params(), D_MAX, checked(stripes(6)))
    periodic = Params().replace(**recovery.RECOVERY, refine=False)
    assert calls == [periodic, Params()] and recovery.PERIODIC["refine"] is False
    assert result.recovery["periodic"] == 1.0
    assert result.recovery["first_params"] == recovery.PERIODIC
    assert result.recovery["kept"] == "retry"
    assert result.recovery["retry_params"] == {"matching_cost": "ad", "message_ambiguity": 0.0,
                                               "refine": True}


def test_a_textured_pair_starts_with_the_given_params_and_records_its_periodicity():
    run, calls = runs(model(jump=10.0))
    rng = np.random.default_rng(1)
    result, _ = with_recovery(run, Params(), D_MAX, checked(rng.random((64, 160, 3))))
    assert calls == [Params()] and result.recovery["periodic"] == 0.0
    assert "first_params" not in result.recovery
    run, calls = runs(model(jump=10.0))
    with_recovery(run, Params(recover=False), D_MAX, checked(stripes(6)))
    assert calls == [Params(recover=False)]


def test_a_periodic_cost_curve_gets_less_confidence_than_a_unimodal_one():
    """The distinctness weight of the messages (reference.distinctness, held to the kernel
    in test_kernels): two equally deep minima a period apart weigh 0, one clear minimum 1."""
    from lss_kernels.reference import kernels as ref
    c = np.arange(24)
    unimodal = 1.0 - np.exp(-((c - 9) / 2.0) ** 2)
    periodic = 1.0 - np.cos(2 * np.pi * c / 6.0) ** 8        # minima every 3 candidates
    weights = ref.distinctness(np.stack([unimodal, periodic]), 0.2)
    assert weights[0] == pytest.approx(1.0) and weights[1] == pytest.approx(0.0, abs=1e-9)


def test_params_recover_is_validated():
    with pytest.raises(ValueError, match="params.recover"):
        Params(recover="yes")


@pytest.mark.slow
def test_a_dark_weak_background_is_recovered(ti_arch, tmp_path):
    """The stress set's dark, weakly textured background: with Eq. 8 alone
    (``background_sweep=0``) AD lets the two surfaces coincide; solve() recognises it and
    the census solve finds the occlusion.  By default the plane sweep places the background
    in the first solve, and no second solve runs."""
    from lss_kernels import solve, stress
    from lss_kernels.io import load_scene
    from lss_kernels.metrics import score
    from lss_kernels.scenes import write_scene
    name, keywords = next(s for s in stress.stress_specs(seed=0, size="small")
                          if s[0] == "weak_bg_dark")
    write_scene(tmp_path / name, None, name=name, **keywords)
    scene = load_scene(tmp_path / name)
    result = solve(scene.left, scene.right, scene.d_max, scene.init_ellipse,
                   params=Params(background_sweep=0.0))
    assert result.recovery["retried"], result.recovery
    assert score(result.disparity, result.occlusion, scene)["occ_f1"] > 0.9
    swept = solve(scene.left, scene.right, scene.d_max, scene.init_ellipse)
    assert not swept.recovery["retried"], swept.recovery
    assert score(swept.disparity, swept.occlusion, scene)["occ_f1"] > 0.9


@pytest.mark.slow
def test_lss_solve_says_it_recovered(ti_arch, tmp_path, capsys):
    import json
    from lss_kernels import stress
    from lss_kernels.apps.cli import main
    from lss_kernels.scenes import write_scene
    name, keywords = next(s for s in stress.stress_specs(seed=0, size="small")
                          if s[0] == "weak_bg_dark")
    write_scene(tmp_path / name, None, name=name, **keywords)
    out = tmp_path / "out"
    assert main(["solve", "--scene", str(tmp_path / name), "--out", str(out), "--arch",
                 ti_arch, "--param", "background_sweep=0"]) == 0
    printed = capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert summary["recovery"].get("kept") == "retry", summary["recovery"]
    assert "the first model collapsed" in printed and "kept the second model" in printed
    assert summary["score"]["occ_f1"] > 0.9


def test_a_periodic_start_that_finds_nothing_falls_back_to_the_given_params():
    """With the periodic parameters the first consensus may hold no confident match under a
    point; the pair is then solved with the given parameters, once."""
    from lss_kernels.model.init import InitError
    calls = []

    def run(params):
        calls.append(params)
        if params.message_ambiguity > 0:
            raise InitError("init: no confident match near the point")
        return model(jump=0.0), len(calls)
    result, extra = with_recovery(run, Params(), D_MAX, checked(stripes(6)))
    assert calls == [Params().replace(**recovery.PERIODIC), Params()]
    assert "no confident match" in result.recovery["first_error"]
    assert result.recovery["retried"] is False and extra == 2


def test_an_init_error_without_a_periodic_switch_is_raised():
    from lss_kernels.model.init import InitError

    def run(params):
        raise InitError("init auto: no foreground found")
    with pytest.raises(InitError, match="no foreground found"):
        with_recovery(run, Params(), D_MAX,
                      checked(np.random.default_rng(2).random((64, 160))))
