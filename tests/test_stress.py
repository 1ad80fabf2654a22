"""The stress set: hard rendered scenes whose folders load and whose ground truth holds what
each family promises (periodic stripes, low contrast, wide occlusions, poor starts)."""
import numpy as np
import pytest

from lss_kernels import stress
from lss_kernels.io import list_scenes, load_scene
from lss_kernels.metrics import score
from lss_kernels.scenes import OUTLINES, check_scene, make_multi_scene, make_scene


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    """The small set of seed 0, written and read back, by name."""
    out = tmp_path_factory.mktemp("stress")
    folders = stress.write_stress_set(out, seed=0, size="small")
    assert sorted(map(str, folders)) == sorted(map(str, list_scenes(out)))
    return {s.name: s for s in map(load_scene, folders)}


def _grey(scene):
    return scene.left.astype(np.float64).mean(axis=-1)


def _period(signal, lags=range(2, 13)):
    """The lag of the largest normalised autocorrelation of a 1-D signal."""
    z = signal - signal.mean()
    corr = [np.dot(z[:-k], z[k:]) / np.sqrt(np.dot(z[:-k], z[:-k]) * np.dot(z[k:], z[k:]))
            for k in lags]
    return list(lags)[int(np.argmax(corr))], max(corr)


def _layers(scene, kind):
    """``(mask, texture)`` of the left-view layers whose texture is of ``kind``."""
    spec = scene.meta["spec"]
    return [(mask, spec[key]) for mask, key in ((scene.fg_left, "texture_fg"),
                                                (~scene.fg_left, "texture_bg"))
            if (spec[key] or {}).get("kind") == kind]


def test_families_and_names(scenes):
    specs = stress.stress_specs(seed=0, size="small")
    names = [name for name, _ in specs]
    assert len(names) >= 24 and len(set(names)) == len(names) == len(scenes)
    families = {}
    for scene in scenes.values():
        families.setdefault(scene.meta["family"], []).append(scene.name)
        assert scene.name.startswith(scene.meta["family"] + "_") and scene.meta["description"]
    assert set(families) == set(stress.STRESS_FAMILIES) and len(families) >= 6
    assert all(3 <= len(v) <= 4 for v in families.values()), families


def test_ground_truth_is_consistent(scenes):
    for name, scene in scenes.items():
        h, w = scene.fg_left.shape
        assert (w, h) == stress.SIZES["small"] and scene.left.shape == scene.right.shape
        assert not (scene.occ_left & scene.fg_left).any(), name
        assert 0.05 < scene.fg_left.mean() < 0.5, name
        assert 0.0 < scene.occ_left.mean() < 0.3, name
        assert np.isfinite(scene.disp_left).all() and scene.disp_left.min() >= 0, name
        assert scene.disp_left.max() + 2 <= scene.d_max and scene.d_max % 16 == 0, name
        # The foreground is nearer than the background next to it, and touches no border.
        assert scene.disp_left[scene.fg_left].min() > np.median(scene.disp_left[~scene.fg_left])
        assert not (scene.fg_left[0].any() or scene.fg_left[-1].any()
                    or scene.fg_left[:, 0].any() or scene.fg_left[:, -1].any()), name
        assert scene.init_ellipse is not None and scene.init_ellipse_cyclopean is not None
        s = score(scene.disp_left, scene.occ_left, scene)
        assert (s["occ_f1"], s["bad4"]) == (1.0, 0.0) and s["n_true_occ"] > 0, name


def test_stripes_are_periodic(scenes):
    striped = [s for s in scenes.values() if s.meta["family"] == "periodic"]
    assert len(striped) >= 3
    checked = 0
    for scene in striped:
        grey = _grey(scene)
        for mask, texture in _layers(scene, "stripes"):
            rows = np.flatnonzero(mask.sum(axis=1) >= 40)
            y = rows[len(rows) // 2]
            xs = np.flatnonzero(mask[y])
            run = xs[(xs >= xs[0]) & (xs < xs[0] + 40)]     # 40 contiguous pixels of the layer
            assert np.array_equal(run, np.arange(run[0], run[0] + 40))
            lag, corr = _period(grey[y, run])
            assert lag == round(texture["period"]) and corr > 0.8, (scene.name, lag, corr)
            checked += 1
    assert checked >= 5


def test_weak_textures_are_low_contrast(scenes):
    weak = [s for s in scenes.values() if s.meta["family"] == "weak"]
    assert len(weak) >= 3 and any(s.meta["spec"]["noise"] > 0 for s in weak)
    checked = 0
    for scene in weak + [scenes["curved_ball_dark"]]:
        grey = _grey(scene)
        for mask, texture in _layers(scene, "low_contrast"):
            values = grey[mask] * 255
            assert values.std() < 3.0, scene.name
            assert np.percentile(values, 99) - np.percentile(values, 1) <= 20, scene.name
            assert abs(values.mean() - 255 * texture["brightness"]) < 6, scene.name
            checked += 1
    assert checked >= 6
    assert sum(_grey(s).mean() < 0.15 for s in weak) >= 1          # a dark pair


def test_curved_backgrounds_are_not_planes(scenes):
    for scene in (s for s in scenes.values() if s.meta["family"] == "curved"):
        bg = ~scene.fg_left
        y, x = np.nonzero(bg)
        a = np.stack([x, y, np.ones_like(x)], -1).astype(np.float64)
        d = scene.disp_left[bg].astype(np.float64)
        residual = d - a @ np.linalg.lstsq(a, d, rcond=None)[0]
        assert np.abs(residual).max() > 2.0, scene.name


def test_wide_occlusions(scenes):
    """The jump family's occluded strip left of the object is as wide as the jump (>= 20 px at
    the small size) and its d_max reaches 48."""
    jumps = [s for s in scenes.values() if s.meta["family"] == "jump"]
    for scene in jumps:
        y = int(np.argmax(scene.fg_left.sum(axis=1)))
        edge = np.flatnonzero(scene.fg_left[y])[0]
        run = 0
        while run < edge and scene.occ_left[y, edge - 1 - run]:
            run += 1
        assert run >= 19, (scene.name, run)
    assert max(s.d_max for s in jumps) == 48


def test_small_jumps(scenes):
    """The fine family's occluded strip left of the object is 1-3 px wide at the small size
    (its jumps are halved there), and its thin object is under 16 px wide."""
    for scene in (s for s in scenes.values() if s.meta["family"] == "fine"):
        y = int(np.argmax(scene.fg_left.sum(axis=1)))
        edge = np.flatnonzero(scene.fg_left[y])[0]
        run = 0
        while run < edge and scene.occ_left[y, edge - 1 - run]:
            run += 1
        assert 1 <= run <= 3, (scene.name, run)
    assert scenes["fine_thin"].fg_left.sum(axis=1).max() < 16


def test_clutter_backgrounds_are_not_one_quadratic(scenes):
    """No quadratic fits the clutter family's visible background within 0.5 px (the small
    size halves the jumps), and the object's strip changes width along its edge: over a box,
    a shelf or a floor it is the jump to them."""
    clutter = [s for s in scenes.values() if s.meta["family"] == "clutter"]
    assert len(clutter) == 4
    for scene in clutter:
        bg = ~scene.fg_left & ~scene.occ_left
        y, x = np.nonzero(bg)
        u = np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], -1).astype(np.float64)
        d = scene.disp_left[bg].astype(np.float64)
        residual = d - u @ np.linalg.lstsq(u, d, rcond=None)[0]
        assert np.abs(residual).max() > 0.5, scene.name
        widths = []
        for row in np.flatnonzero(scene.fg_left.sum(axis=1) >= 8):
            edge = np.flatnonzero(scene.fg_left[row])[0]
            run = 0
            while run < edge and scene.occ_left[row, edge - 1 - run]:
                run += 1
            widths.append(run)
        assert max(widths) - min(widths) >= 3, (scene.name, widths)


def test_init_family_starts(scenes):
    """Half covers: about half of the object; spills: the whole object and 30 % more."""
    for name, (lo, hi) in {"init_half_inside": (0.4, 0.6), "init_half_side": (0.35, 0.65)}.items():
        scene = scenes[name]
        h, w = scene.fg_left.shape
        y, x = np.mgrid[0:h, 0:w]
        cx, cy, rx, ry = scene.init_ellipse
        init = ((x - cx) / rx) ** 2 + ((y - cy) / ry) ** 2 <= 1
        assert lo < (init & scene.fg_left).sum() / scene.fg_left.sum() < hi, name
    for name in ("init_spill30", "init_spill30_left"):
        scene = scenes[name]
        cx, cy, rx, ry = scene.init_ellipse
        tcx, tcy, trx, try_ = scene.meta["ellipse"]
        assert rx * ry >= 1.3 * trx * try_ and cx - rx <= tcx - 1.3 * trx + 1e-9, name


def test_generation_is_deterministic_per_seed():
    a, b = stress.stress_specs(seed=3, size="small"), stress.stress_specs(seed=3, size="small")
    assert a == b and a != stress.stress_specs(seed=4, size="small")
    name, keywords = a[5]
    kwargs = {k: v for k, v in keywords.items() if k != "meta"}
    one, two = make_scene(None, **kwargs), make_scene(None, **kwargs)
    for key in ("left", "right", "disp_left", "occ_left"):
        np.testing.assert_array_equal(getattr(one, key), getattr(two, key), err_msg=name)


def test_medium_size_scales_the_geometry():
    small = dict(stress.stress_specs(seed=0, size="small"))
    medium = dict(stress.stress_specs(seed=0, size="medium"))
    assert (medium["jump_60_far"]["width"], medium["jump_60_far"]["height"]) == (320, 240)
    np.testing.assert_allclose(medium["jump_60_far"]["ellipse"],
                               2 * np.asarray(small["jump_60_far"]["ellipse"]))
    assert medium["jump_60_far"]["d_fg"][5] == pytest.approx(2 * small["jump_60_far"]["d_fg"][5])


def test_command_line(tmp_path, capsys):
    assert stress.main([str(tmp_path / "set"), "--size", "small", "--seed", "2"]) == 0
    assert len(list_scenes(tmp_path / "set")) == len(stress.stress_specs())
    assert "wrote" in capsys.readouterr().out
    with pytest.raises(SystemExit) as exc:
        stress.main([str(tmp_path / "x"), "--size", "huge"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and len(err.strip().splitlines()) == 1 and "--size" in err
    (tmp_path / "file").write_text("")
    assert stress.main([str(tmp_path / "file"), "--size", "small"]) == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "not a folder" in err


#: One scene per family, seed 0, and its occlusion-F1 floor (about 0.05 under what the default
#: solve measured; the recovery solve rescues curved_ball_dark and weak_bg_dark).  The small
#: size halves the jumps but keeps texture scales, so its periodic and fine scenes lie below
#: the scale their families test (stripes of 3-8 px over jumps of 9-10 px, jumps of 1.5-3.5 px:
#: F1 0-0.9 by the rounding of a single pixel, or, for periodic_both_p7, by which of the
#: stripes' false matches the boundary falls into: one machine's float rounding sends it, at
#: iteration 220, to a wrong model that holds F1 0.29 to the 1500-iteration cap, another's
#: passed 0.45, with the same code); those two families are solved at the medium size.
FAMILY_FLOORS = {"camouflage_noise_noisy": 0.85, "curved_ball_dark": 0.8,
                 "init_spill30": 0.9, "jump_60_far": 0.95, "shape_L": 0.85,
                 "weak_bg_dark": 0.9, "clutter_boxes": 0.85}
MEDIUM_FLOORS = {"periodic_bg_p6": 0.83, "fine_jump5_far": 0.88}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(FAMILY_FLOORS) + sorted(MEDIUM_FLOORS))
def test_each_family_solves_above_its_floor(scenes, ti_arch, name):
    from lss_kernels import solve
    assert {n.split("_")[0] for n in {**FAMILY_FLOORS, **MEDIUM_FLOORS}} == \
        set(stress.STRESS_FAMILIES)
    if name in MEDIUM_FLOORS:
        keywords = dict(stress.stress_specs(seed=0, size="medium"))[name]
        scene = make_scene(None, **{k: v for k, v in keywords.items() if k != "meta"})
    else:
        scene = scenes[name]
    result = solve(scene.left, scene.right, scene.d_max, scene.init_ellipse)
    f1 = score(result.disparity, result.occlusion, scene)["occ_f1"]
    assert f1 >= {**FAMILY_FLOORS, **MEDIUM_FLOORS}[name], (name, f1, result.recovery)


@pytest.mark.slow
def test_a_striped_pair_that_looks_sound_under_ad_is_found_by_the_periodicity_check(ti_arch):
    """Seed 1's medium ``periodic_both_p5_p8``: with the paper's AD cost the model looks
    sound (a jump, in front, in range) but lies periods off (F1 0.12); the left image's
    periodicity sends it to the distinctness-weighted solve first (F1 1.00)."""
    from lss_kernels import solve
    from lss_kernels.checks.recovery import PERIODIC
    name, keywords = next(s for s in stress.stress_specs(seed=1, size="medium")
                          if s[0] == "periodic_both_p5_p8")
    keywords.pop("meta")
    scene = make_scene(None, **keywords)
    result = solve(scene.left, scene.right, scene.d_max, scene.init_ellipse)
    assert result.recovery["periodic"] > 0.5 and result.recovery["first_params"] == PERIODIC
    assert score(result.disparity, result.occlusion, scene)["occ_f1"] >= 0.95


def test_random_scenes_are_valid_varied_and_deterministic():
    specs = stress.random_specs(seed=5, count=24, size="small")
    assert specs == stress.random_specs(seed=5, count=24, size="small")
    assert specs != stress.random_specs(seed=6, count=24, size="small")
    assert [name for name, _ in specs] == [f"random_{k:02d}" for k in range(24)]
    slanted = lambda d: isinstance(d, tuple) and any(d[:5])
    kw = [k for _, k in specs]
    assert {k["outline"] for k in kw} == set(OUTLINES)
    assert any(slanted(k["d_bg"]) for k in kw) and any(not slanted(k["d_bg"]) for k in kw)
    assert {"random", "palette", "low_contrast"} <= {k["texture_fg"] for k in kw}
    assert 0.0 <= min(k["noise"] for k in kw) and max(k["noise"] for k in kw) <= 0.02
    for name, keywords in specs[:6]:
        scene = make_scene(None, **{k: v for k, v in keywords.items() if k != "meta"})
        assert scene.left.shape[:2] == (120, 160) and scene.fg_left.any(), name
        assert scene.disp_left.min() >= 0, name
        assert (scene.disp_left[scene.fg_left].min()
                > np.median(scene.disp_left[~scene.fg_left & ~scene.occ_left])), name


def test_check_scene_refuses_what_make_scene_would():
    check_scene(width=64, height=48, d_fg=12.0, d_bg=4.0)
    with pytest.raises(ValueError, match="d_bg: disparity must be >= 0"):
        check_scene(width=64, height=48, d_fg=12.0, d_bg=(0, 0, 0, 0.2, 0, -1.0))
    with pytest.raises(ValueError, match="in front of the background"):
        check_scene(width=64, height=48, d_fg=4.0, d_bg=6.0)


def test_command_line_random(tmp_path, capsys):
    assert stress.main([str(tmp_path / "r"), "--size", "small", "--random", "3"]) == 0
    folders = list_scenes(tmp_path / "r")
    assert len(folders) == 3 and "random" in capsys.readouterr().out
    assert load_scene(folders[0]).meta["family"] == "random"
    with pytest.raises(SystemExit) as exc:
        stress.main([str(tmp_path / "x"), "--random", "-1"])
    assert exc.value.code == 2 and "--random" in capsys.readouterr().err


@pytest.mark.slow
def test_a_dark_object_over_bright_texture_keeps_its_interior(ti_arch):
    """Seed 1's medium ``random_16``: an L-shaped object of 8 dark grey levels, 3 px in front
    of a bright palette.  Inside it the data term of Eq. 2 is weak and noisy; with the paper's
    step every pixel moves (``narrow_band=0``), sign flips add up to holes far from the
    boundary, each with a false occlusion strip, and the boundary never settles (950 hole
    pixels after 400 iterations; F1 0.58 at the 1500 cap).  The narrow band moves phi only
    near the boundary: F1 0.95 in 300 iterations, no hole."""
    from scipy.ndimage import binary_fill_holes

    from lss_kernels import Params, solve
    name, keywords = stress.random_specs(seed=1, count=17, size="medium")[16]
    assert name == "random_16" and keywords["texture_fg"] == "low_contrast"
    keywords.pop("meta", None)
    scene = make_scene(None, **keywords)

    def holes(result):
        return int((binary_fill_holes(result.foreground) & ~result.foreground).sum())

    banded = solve(scene.left, scene.right, scene.d_max, scene.init_ellipse)
    assert score(banded.disparity, banded.occlusion, scene)["occ_f1"] >= 0.85
    assert holes(banded) < 20 and banded.iterations < 600
    everywhere = solve(scene.left, scene.right, scene.d_max, scene.init_ellipse,
                       params=Params(narrow_band=0.0, max_iterations=400))
    assert holes(everywhere) > 200


@pytest.mark.slow
def test_a_dark_background_is_placed_by_the_plane_sweep(ti_arch):
    """Seed 2's medium ``random_12``: a textured box 37.5 px in front of a dark background of
    8 grey levels under noise, the hand ellipse inside the box.  The background's consensus
    has no precision, so Eq. 8 fits Theta_2 to the box's uncovered rim: both layers sit on
    the box and the foreground vanishes (F1 0).  The plane sweep finds the background's
    disparity in the sum of its standardised costs, and the box is recovered."""
    from lss_kernels import Params, Solver
    name, keywords = stress.random_specs(seed=2, count=13, size="medium")[12]
    assert name == "random_12" and keywords["texture_bg"] == "low_contrast"
    keywords.pop("meta", None)
    scene = make_scene(None, **keywords)
    true_bg = float(np.median(scene.disp_left[~scene.fg_left]))

    def run(params):
        solver = Solver(scene.left, scene.right, scene.d_max, scene.init_ellipse, params=params)
        try:
            return solver.run(), solver.history
        finally:
            solver.close()

    swept, history = run(Params())
    planes = [s["background_plane"] for s in history if s["background_plane"] is not None]
    assert planes and abs(planes[0] - true_bg) <= 2.0
    assert score(swept.disparity, swept.occlusion, scene)["occ_f1"] >= 0.95
    fitted, _ = run(Params(background_sweep=0.0, max_iterations=300))
    assert not fitted.foreground.any()


# ------------------------------------------------------------------------------ multi-object
@pytest.fixture(scope="module")
def multi(tmp_path_factory):
    """The small multi-object family of seed 0, written and read back, by name."""
    out = tmp_path_factory.mktemp("multi")
    folders = stress.write_stress_set(out, seed=0, size="small", multi=True)
    return {s.name: s for s in map(load_scene, folders)}


def _on_clicked_surface(scene):
    """The clicked object's disparity surface at every pixel (extended beyond its outline)."""
    theta = np.array(scene.meta["objects"][scene.meta["clicked"]]["theta"])
    y, x = np.mgrid[0:scene.disp_left.shape[0], 0:scene.disp_left.shape[1]].astype(np.float64)
    return np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], -1) @ theta


def test_multi_family_is_apart_from_the_stress_set(multi):
    names = [name for name, _ in stress.stress_specs(seed=0, size="small")]
    assert len(names) == 36 and not any(n.startswith("multi") for n in names)
    specs = stress.multi_specs(seed=0, size="small")
    assert len(specs) >= 8 and sorted(n for n, _ in specs) == sorted(multi)


def test_multi_ground_truth_is_the_clicked_objects(multi):
    """Per scene: 3-6 objects, layers_left agrees with fg_left, the click lies on the clicked
    object where both cameras see it, the band leaves out nearer surfaces and never holds the
    object's pixels hidden by another, and the truth scores perfectly."""
    for name, scene in multi.items():
        meta, (h, w) = scene.meta, scene.fg_left.shape
        assert (w, h) == stress.MULTI_SIZES["small"] and meta["family"] == "multi", name
        assert 3 <= len(meta["objects"]) <= 6 and meta["description"], name
        assert scene.init_ellipse is None and scene.d_max == 32.0, name
        assert scene.disp_left.max() + 2 <= scene.d_max and scene.disp_left.min() >= 0, name
        assert 2 / 255 <= meta["spec"]["noise"] <= 5 / 255, name
        np.testing.assert_array_equal(scene.fg_left, scene.layers_left == meta["clicked"] + 1)
        assert scene.layers_left.max() == len(meta["objects"]), name
        x, y = (int(round(v)) for v in scene.init_point)
        assert scene.fg_left[y, x] and not scene.occ_left[y, x], name
        nearer = ~scene.fg_left & (scene.disp_left > _on_clicked_surface(scene) + 1e-3)
        band = scene.roi_fg | scene.roi_bg
        assert not (band & nearer).any() and not (scene.roi_fg & scene.roi_bg).any(), name
        np.testing.assert_array_equal(scene.roi_fg, band & scene.fg_left)
        assert not (scene.roi_fg & scene.occ_left).any(), name
        assert (scene.roi_bg & scene.occ_left).sum() > 50, name
        s = score(scene.disp_left, scene.occ_left, scene)
        assert (s["occ_f1"], s["bad4"]) == (1.0, 0.0), name


def test_multi_family_holds_what_it_promises(multi):
    """Objects before the clicked one in most scenes, rods, a neighbour a few pixels behind,
    a weakly textured clicked object, a curved wall."""
    for name, scene in multi.items():
        fg = scene.fg_left
        beside = fg.copy()
        beside[1:] |= fg[:-1]
        beside[:-1] |= fg[1:]
        beside[:, 1:] |= fg[:, :-1]
        beside[:, :-1] |= fg[:, 1:]
        before = scene.disp_left > _on_clicked_surface(scene) + 1
        assert (before & beside).sum() > 20, name     # something nearer borders the object
    rods = [o for s in multi.values() for o in s.meta["objects"]
            if o["box"] is not None and o["box"][3] <= 1.0 and o["box"][2] > 10]
    assert len(rods) >= 5 and any(o["angle"] for o in rods)
    neighbour = multi["multi_neighbour"].meta
    gap = neighbour["objects"][2]["theta"][5] - neighbour["objects"][0]["theta"][5]
    assert 0 < gap <= 2                                  # 6 px at the photo size
    weak = multi["multi_weak"]
    assert weak.meta["spec"]["objects"][weak.meta["clicked"]]["texture"]["kind"] == "low_contrast"
    assert np.ptp(multi["multi_curved"].meta["theta_bg"][:3]) > 0


def test_multi_family_is_deterministic_and_scales():
    a, b = stress.multi_specs(seed=3, size="small"), stress.multi_specs(seed=3, size="small")
    assert a == b and a != stress.multi_specs(seed=4, size="small")
    kwargs = {k: v for k, v in a[1][1].items() if k != "meta"}
    one, two = make_multi_scene(**kwargs), make_multi_scene(**kwargs)
    for key in ("left", "right", "disp_left", "occ_left", "layers_left"):
        np.testing.assert_array_equal(getattr(one, key), getattr(two, key), err_msg=key)
    photo = dict(stress.multi_specs(seed=3, size="photo"))["multi_rod"]
    small = dict(a)["multi_rod"]
    assert (photo["width"], photo["height"], photo["d_max"]) == (672, 560, 128.0)
    np.testing.assert_allclose(photo["objects"][0]["box"],
                               4 * np.asarray(small["objects"][0]["box"]))
    with pytest.raises(ValueError, match="size: unknown 'huge' for the multi family"):
        stress.multi_specs(size="huge")


def test_command_line_multi(tmp_path, capsys):
    assert stress.main([str(tmp_path / "m"), "--multi", "--size", "small", "--seed", "1"]) == 0
    assert len(list_scenes(tmp_path / "m")) == 8 and "multi-object" in capsys.readouterr().out
    with pytest.raises(SystemExit) as exc:
        stress.main([str(tmp_path / "x"), "--multi", "--random", "3"])
    assert exc.value.code == 2 and "--multi" in capsys.readouterr().err
    assert stress.main([str(tmp_path / "p"), "--size", "photo"]) == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "size: unknown 'photo'" in err


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_multi_family_renders_at_every_size(seed):
    """Seeds 0-2 give valid scenes at the medium and photo sizes (d_max 64 and 128)."""
    for size, d_max in (("medium", 64.0), ("photo", 128.0)):
        for name, keywords in stress.multi_specs(seed, size):
            scene = make_multi_scene(**{k: v for k, v in keywords.items() if k != "meta"})
            assert scene.d_max == d_max and scene.fg_left.sum() > 0.02 * scene.fg_left.size


# ------------------------------------------------------------------------------- periodic set
def test_periodic_set_holds_what_it_promises(tmp_path):
    folders = stress.write_stress_set(tmp_path, seed=0, size="small", periodic=True)
    scenes = [load_scene(f) for f in folders]
    assert len(scenes) == 12 and all(s.name.startswith("periodic_") for s in scenes)
    both = fg_only = checked = 0
    for scene in scenes:
        spec = scene.meta["spec"]
        fg, bg = spec["texture_fg"], spec["texture_bg"]
        assert fg["kind"] == "stripes" and 3 <= fg["period"] <= 32, scene.name
        if bg["kind"] == "stripes":
            both += 1
            assert 3 <= bg["period"] <= 32, scene.name
        else:
            fg_only += 1
            assert bg["kind"] == "low_contrast", scene.name
        s = score(scene.disp_left, scene.occ_left, scene)
        assert (s["occ_f1"], s["bad4"]) == (1.0, 0.0) and s["n_true_occ"] > 0, scene.name
        # vertical stripes of a period the rows show
        for mask, texture in _layers(scene, "stripes"):
            if texture.get("angle", 0.0) == 0 and texture["period"] <= 12:
                y = np.flatnonzero(mask.sum(axis=1) >= 40)[0] + 2
                xs = np.flatnonzero(mask[y])[:40]
                lag, corr = _period(_grey(scene)[y, xs], lags=range(2, 16))
                turns = lag / texture["period"]           # a whole number of periods
                assert abs(turns - round(turns)) * texture["period"] <= 1 and corr > 0.6, \
                    (scene.name, lag)
                checked += 1
    assert both >= 9 and fg_only == 3 and checked >= 6
    angles = {s.meta["spec"]["texture_fg"].get("angle", 0.0) for s in scenes}
    assert len(angles) >= 3                       # vertical, at an angle and crossed
    periods = [s.meta["spec"]["texture_fg"]["period"] for s in scenes]
    assert min(periods) < 6 and max(periods) > 20


def test_periodic_set_is_deterministic_and_apart_from_the_stress_set(tmp_path, capsys):
    a = stress.periodic_specs(seed=1, size="small")
    assert a == stress.periodic_specs(seed=1, size="small")
    assert a != stress.periodic_specs(seed=2, size="small")
    assert not {n for n, _ in a} & {n for n, _ in stress.stress_specs(seed=1, size="small")}
    assert stress.main([str(tmp_path / "p"), "--periodic", "--size", "small"]) == 0
    assert len(list_scenes(tmp_path / "p")) == 12 and "periodic" in capsys.readouterr().out
    with pytest.raises(SystemExit) as exc:
        stress.main([str(tmp_path / "x"), "--periodic", "--multi"])
    assert exc.value.code == 2 and "one at a time" in capsys.readouterr().err
    with pytest.raises(ValueError, match="one of random, multi and periodic"):
        stress.write_stress_set(tmp_path / "y", periodic=True, random=3)
