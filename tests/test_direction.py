"""Swapped views are recognised before the solve (``lss_kernels.checks.direction``) and reported."""
import json
import re
import warnings

import imageio.v3 as iio
import numpy as np
import pytest

from lss_kernels import Params
from lss_kernels.checks import direction
from lss_kernels.checks.pair import CheckedPair
from lss_kernels.checks.recovery import SwappedViewsWarning, with_recovery
from lss_kernels.scenes import make_scene


def checked(left, right, d_max):
    """The pair as :func:`lss_kernels.solve` checks it, started automatically."""
    return CheckedPair(left, right, d_max, "auto", "left", Params())


def shifted_pair(shift=4, shape=(40, 96), seed=0):
    """Random texture as the left view and its copy moved left by ``shift`` as the right
    one: ``right[:, x] = left[:, x + shift]``, so left pixel x matches right x - shift."""
    rng = np.random.default_rng(seed)
    left = rng.random(shape).astype(np.float32)
    right = np.roll(left, -shift, axis=1)
    return left, right


def test_a_pair_in_the_stated_direction_is_not_swapped_and_the_reversed_one_is():
    left, right = shifted_pair()
    facts = direction.match_direction(left, right, 10)
    assert not facts["swapped"] and facts["stated"] > 0.9 > 0.05 > facts["reversed"]
    back = direction.match_direction(right, left, 10)
    assert back["swapped"] and back["reversed"] > 0.9 and back["stated"] < 0.05


def test_the_verdict_holds_for_colour_images_and_above_the_check_width():
    left, right = shifted_pair(shift=6, shape=(40, 700))
    colour = lambda g: np.repeat(g[..., None], 3, axis=2)
    facts = direction.match_direction(colour(right), colour(left), 20)
    assert facts["scale"] == 3 and facts["swapped"]


def test_no_parallax_no_texture_or_stripes_give_no_verdict():
    left, _ = shifted_pair()
    same = direction.match_direction(left, left, 10)
    assert not same["swapped"] and same["stated"] < 0.1 and same["reversed"] < 0.1
    flat = direction.match_direction(np.full((40, 96), 0.5), np.full((40, 96), 0.5), 10)
    assert flat["textured"] == 0 and not flat["swapped"]
    x = np.arange(96)
    stripes = np.tile((np.sin(2 * np.pi * x / 6) > 0).astype(np.float32), (40, 1))
    striped = direction.match_direction(np.roll(stripes, 2, axis=1), stripes, 10)
    assert not striped["swapped"]


def test_the_rendered_scene_is_stated_and_its_mirror_swapped():
    scene = make_scene("tiny")
    assert not direction.match_direction(scene.left, scene.right, scene.d_max)["swapped"]
    assert direction.match_direction(scene.right, scene.left, scene.d_max)["swapped"]


def sound_model():
    """A Result-like sound model (a 6 px jump in front, inside d_max = 10) for ``with_recovery``."""
    from types import SimpleNamespace
    phi = -np.ones((20, 30))
    phi[5:15, 10:20] = 1.0
    surface = np.where(phi > 0, 8.0, 2.0)
    return SimpleNamespace(phi=phi, theta_fg=np.array([0, 0, 0, 0, 0, 8.0]),
                           theta_bg=np.array([0, 0, 0, 0, 0, 2.0]), foreground=phi > 0,
                           surface=surface, disparity=surface,
                           occlusion=np.zeros((20, 30), bool), recovery={})


def test_with_recovery_warns_before_the_solve_and_records_the_check():
    left, right = shifted_pair()
    warned_before = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")

        def run(params):
            warned_before.append(sum(issubclass(w.category, SwappedViewsWarning)
                                     for w in caught))
            return sound_model(), None
        result, _ = with_recovery(run, Params(), 10.0, checked(right, left, 10.0))
    swapped = [w for w in caught if issubclass(w.category, SwappedViewsWarning)]
    assert warned_before == [1] and result.recovery["direction"]["swapped"]
    assert "pass the two images the other way round" in str(swapped[0].message)

    def solve_sound(params):
        return sound_model(), None
    with warnings.catch_warnings():
        warnings.simplefilter("error", SwappedViewsWarning)
        result, _ = with_recovery(solve_sound, Params(), 10.0,
                                  checked(left, right, 10.0))
    assert result.recovery["direction"]["swapped"] is False
    assert result.recovery["range"]["short"] is False
    result, _ = with_recovery(solve_sound, Params(), 10.0)   # no pair: no check
    assert "direction" not in result.recovery and "range" not in result.recovery
    # swapped: the range of the stated direction says nothing, and is not checked
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SwappedViewsWarning)
        result, _ = with_recovery(solve_sound, Params(), 10.0,
                                  checked(right, left, 10.0))
    assert result.recovery["range"] == {}


def test_a_range_shorter_than_the_shift_is_short_and_a_longer_one_is_not():
    left, right = shifted_pair(shift=12)
    short = direction.match_range(left, right, 6)
    assert short["short"] and short["beyond"] > 0.9
    enough = direction.match_range(left, right, 16)
    assert not enough["short"] and enough["beyond"] < 0.05
    # beyond twice the range nothing is looked at: no verdict of shortness
    assert not direction.match_range(left, right, 4)["short"]
    # no texture: no verdict
    flat = direction.match_range(np.full((40, 96), 0.5), np.full((40, 96), 0.5), 6)
    assert flat["textured"] == 0 and not flat["short"]


def test_a_gain_between_the_views_does_not_look_like_a_short_range():
    """A right camera 15 % brighter or darker (exposure) raises every true match's cost; the
    rendered scene's shifts beyond the range then matched the brightness better on 15-22 %
    of its textured pixels, a false alarm.  Counted only where they win on the window's
    detail too, they do not."""
    scene = make_scene("easy")                 # foreground at 24 px, d_max 26
    for gain in (0.85, 1.15):
        enough = direction.match_range(scene.left, scene.right * gain, scene.d_max)
        assert not enough["short"] and enough["beyond"] < 0.02, gain


def test_the_rendered_scene_with_a_short_range_warns_before_the_solve():
    from lss_kernels.checks.recovery import ShortRangeWarning
    scene = make_scene("easy", seed=1)                  # foreground at 24 px, d_max 26
    warned_before = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")

        def run(params):
            warned_before.append(len(caught))
            return sound_model(), None
        result, _ = with_recovery(run, Params(), 14.0,
                                  checked(scene.left, scene.right, 14.0))
    assert warned_before == [1] and issubclass(caught[0].category, ShortRangeWarning)
    assert str(caught[0].message).startswith("the search range looks too short: ")
    assert str(caught[0].message).endswith("give a larger d_max (--dmax)")
    assert result.recovery["range"]["short"] and result.recovery["range"]["beyond"] > 0.2
    with warnings.catch_warnings():
        warnings.simplefilter("error", ShortRangeWarning)
        result, _ = with_recovery(run, Params(), scene.d_max,
                                  checked(scene.left, scene.right, scene.d_max))
    assert not result.recovery["range"]["short"]


def test_lss_solve_prints_the_warning_and_records_it(ti_arch, tmp_path, capsys):
    from lss_kernels.apps.cli import main
    scene = make_scene("tiny")
    for name, image in (("left.png", scene.left), ("right.png", scene.right)):
        iio.imwrite(tmp_path / name, (image * 255).astype(np.uint8))
    out = tmp_path / "out"
    assert main(["solve", str(tmp_path / "right.png"), str(tmp_path / "left.png"), "--dmax",
                 str(scene.d_max), "--init", "ellipse:32,24,10,8", "--out", str(out),
                 "--arch", ti_arch, "--quiet", "--param", "max_iterations=3",
                 "--param", "recover=False"]) == 0
    err = capsys.readouterr().err
    assert "lss solve: warning: the views look swapped" in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["recovery"]["direction"]["swapped"] is True
    # the views as given, with a range shorter than the foreground's 12 px
    assert main(["solve", str(tmp_path / "left.png"), str(tmp_path / "right.png"), "--dmax",
                 "8", "--init", "ellipse:32,24,10,8", "--out", str(out), "--arch", ti_arch,
                 "--quiet", "--param", "max_iterations=3", "--param", "recover=False"]) == 0
    err = capsys.readouterr().err
    assert "lss solve: warning: the search range looks too short" in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["recovery"]["range"]["short"] is True


def test_named_warnings_give_the_library_warnings_again_with_the_name_also_on_failure():
    from lss_kernels.checks.recovery import UnreliableStartWarning, named_warnings
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with named_warnings("scene_a"):
            warnings.warn(SwappedViewsWarning("the views look swapped"))
            warnings.warn(UserWarning("another library's"))
            warnings.warn(UnreliableStartWarning("init auto: periodic"))
            assert caught == []                     # held until the end
        with pytest.raises(RuntimeError, match="solve failed"):
            with named_warnings("scene_b"):
                warnings.warn(SwappedViewsWarning("the views look swapped"))
                raise RuntimeError("solve failed")
    got = [(w.category, str(w.message)) for w in caught]
    assert got == [(SwappedViewsWarning, "scene_a: the views look swapped"),
                   (UserWarning, "another library's"),
                   (UnreliableStartWarning, "scene_a: init auto: periodic"),
                   (SwappedViewsWarning, "scene_b: the views look swapped")]


@pytest.mark.slow
def test_lss_eval_names_the_scene_whose_views_look_swapped(ti_arch, tmp_path, capsys):
    from lss_kernels.apps.cli import main
    from lss_kernels.scenes import write_scene
    scene = write_scene(tmp_path / "data" / "mirror", "tiny", name="mirror")
    # the views swapped: a sound scene folder whose matches run the other way
    iio.imwrite(tmp_path / "data" / "mirror" / "left.png",
                (scene.right * 255).astype(np.uint8))
    iio.imwrite(tmp_path / "data" / "mirror" / "right.png",
                (scene.left * 255).astype(np.uint8))
    assert main(["eval", str(tmp_path / "data"), "--methods", "lss", "--out",
                 str(tmp_path / "out"), "--arch", ti_arch, "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "lss eval: warning: mirror: the views look swapped" in err


def test_the_estimated_range_of_a_shifted_pair_is_its_shift_with_the_margin():
    left, right = shifted_pair(shift=12, shape=(60, 200), seed=3)
    facts = direction.estimate_range(left, right)
    assert facts["farthest"] == 12 and facts["scale"] == 1
    assert facts["d_max"] == 24                          # 8 * ceil((1.15 * 12 + 8) / 8)
    assert facts["matches"] > 0.5 * 56 * 196             # most windows match distinctly
    narrow = direction.estimate_range(*shifted_pair(shift=8, shape=(60, 20), seed=3))
    assert narrow["farthest"] == 8 and narrow["d_max"] == 16   # 24, but below the width 20


@pytest.mark.parametrize("name", ["easy", "slanted"])
def test_the_estimated_range_holds_the_rendered_scenes_disparities(name):
    scene = make_scene(name)
    largest = float(np.nanmax(scene.disp_left))
    facts = direction.estimate_range(scene.left, scene.right)
    assert largest - 1 <= facts["farthest"] <= largest + 2
    assert largest < facts["d_max"] <= 1.15 * largest + 16


def test_far_repeated_matches_of_a_small_patch_do_not_widen_the_estimate():
    """A copy of a few windows 60 px off in the right view (repeated texture) matches
    distinctly and both ways, but as a run under RANGE_SHARE of the matches it is dropped."""
    left, right = shifted_pair(shift=10, shape=(80, 240), seed=4)
    right = right.copy()
    right[30:34, 20:30] = left[30:34, 80:90]           # left x in 80..89 now also at x - 60
    assert direction.estimate_range(left, right)["farthest"] == 10


def test_a_pair_without_texture_has_no_estimate():
    flat = np.full((40, 96), 0.5, np.float32)
    with pytest.raises(ValueError, match=r"^left, right: 0 distinct matches, too few to "
                                         r"estimate d_max \(at least 200\); give it$"):
        direction.estimate_range(flat, flat)


def test_lss_solve_without_dmax_suggests_the_estimate_and_writes_nothing(tmp_path, capsys):
    from lss_kernels.apps.cli import main
    scene = make_scene("easy")                          # foreground at 24 px
    for side in ("left", "right"):
        iio.imwrite(tmp_path / f"{side}.png",
                    (getattr(scene, side) * 255).round().astype(np.uint8))
    out = tmp_path / "out"
    assert main(["solve", str(tmp_path / "left.png"), str(tmp_path / "right.png"),
                 "--out", str(out)]) == 2
    error = capsys.readouterr().err.strip().splitlines()[-1]
    found = re.fullmatch(r"lss solve: error: --dmax: required with LEFT RIGHT; this pair's "
                         r"distinct matches reach (\d+) px, so try --dmax (\d+) \(an estimate: "
                         r"a layer without texture may lie beyond it\)", error)
    assert found, error
    assert 23 <= int(found[1]) <= 26 and int(found[2]) == 40
    assert not out.exists()


def one_period_jump_pair():
    """``periodic_same_coarse`` of ``lss_kernels.stress --periodic --seed 1``: stripes of
    19.3 px on both layers, the jump about one period.  Its teeth a period apart lie on both
    sides of 0, and the reversed direction's happen to fall nearer whole pixels: it wins 77 %
    of the textured pixels, the stated one 13 %."""
    stripes = {"kind": "stripes", "period": 19.29610576646572}
    return make_scene(None, seed=1007, width=320, height=240,
                      d_fg=[0, 0, 0, 0, 0, 28.768780715514506],
                      d_bg=[0, 0, 0, 0, 0, 9.510639874392142],
                      ellipse=[163.41780076730646, 121.68335334506386, 73.01819806274804,
                               77.92721654451306],
                      texture_fg=stripes, texture_bg=stripes, d_max_step=16)


def test_a_periodic_pair_gets_no_swapped_verdict_from_teeth_on_both_sides():
    scene = one_period_jump_pair()
    pair = checked(scene.left, scene.right, scene.d_max)
    assert pair.direction["swapped"]            # the sub-pixel luck of the teeth
    assert pair.periodic >= 0.05                # PERIODIC_AREA: the pair counts as periodic

    def solve_sound(params):
        return sound_model(), None
    with warnings.catch_warnings():
        warnings.simplefilter("error", SwappedViewsWarning)
        result, _ = with_recovery(solve_sound, Params(recover=False), scene.d_max, pair)
    assert result.recovery["direction"]["swapped"] is False
    assert result.recovery["direction"]["periodic"] is True
    assert "short" in result.recovery["range"]        # the range is checked as usual
    # a pair with no periodic texture keeps its verdict: the tiny scene's mirror
    tiny = make_scene("tiny")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result, _ = with_recovery(solve_sound, Params(recover=False), tiny.d_max,
                                  checked(tiny.right, tiny.left, tiny.d_max))
    assert any(issubclass(w.category, SwappedViewsWarning) for w in caught)
    assert result.recovery["direction"]["swapped"] is True
    assert "periodic" not in result.recovery["direction"]
