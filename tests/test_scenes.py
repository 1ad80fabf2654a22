"""Rendered scenes (two layers, or several objects): the images agree with their exact ground
truth."""
import numpy as np
import pytest

from lss_kernels.io import load_scene
from lss_kernels.metrics import band_from_foreground, boundary_from_foreground, score
from lss_kernels.scenes import (PRESETS, disparity_coefficients, make_multi_scene, make_scene,
                                 write_multi_scene, write_scene)


def _grid(scene):
    h, w = scene.disp_left.shape
    return np.mgrid[0:h, 0:w]


def _u(x, y):
    return np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], -1).astype(np.float64)


@pytest.mark.parametrize("preset", ["easy", "tiny"])
def test_fronto_parallel_pair_matches_truth_exactly(preset):
    """Integer disparities: every visible left pixel lands on a right pixel of the same colour."""
    scene = make_scene(preset, seed=4)
    y, x = _grid(scene)
    xr = x - scene.disp_left.astype(int)
    visible = ~scene.occ_left
    assert visible.mean() > 0.7 and (xr[visible] >= 0).all()
    np.testing.assert_allclose(scene.left[visible], scene.right[y[visible], xr[visible]],
                               atol=1e-5)
    # Occluded background pixels show something else in the right view (the foreground).
    inner = scene.occ_left & (xr >= 0)
    assert inner.any()
    assert np.abs(scene.left[inner] - scene.right[y[inner], xr[inner]]).max() > 0.05


def test_slanted_pair_matches_truth():
    """Non-integer disparities: the right image sampled at x - d reproduces the left image up to
    linear interpolation of the texture, away from depth discontinuities."""
    scene = make_scene("slanted", noise=0.0)
    h, w = scene.disp_left.shape
    y, x = _grid(scene)
    xr = x - scene.disp_left
    assert np.abs(xr - np.round(xr)).max() > 0.3
    edges = scene.occ_left | boundary_from_foreground(scene.fg_left) \
        | boundary_from_foreground(~scene.fg_left)
    near = np.logical_or(*band_from_foreground(edges, radius=2))  # within 2 px of an edge
    ok = ~scene.occ_left & ~near & (xr >= 0) & (xr <= w - 1)
    i0 = np.clip(np.floor(xr).astype(int), 0, w - 2)
    f = (xr - i0)[..., None]
    sampled = (1 - f) * scene.right[y, i0] + f * scene.right[y, i0 + 1]
    err = np.abs(sampled - scene.left).max(-1)[ok]
    assert ok.sum() > 0.6 * h * w
    assert np.median(err) < 0.02 and err.max() < 0.15


def test_disparity_is_the_quadratic():
    scene = make_scene("slanted")
    y, x = _grid(scene)
    u = _u(x, y)
    theta_fg, theta_bg = (np.array(scene.meta[k]) for k in ("theta_fg", "theta_bg"))
    expected = np.where(scene.fg_left, u @ theta_fg, u @ theta_bg)
    np.testing.assert_allclose(scene.disp_left, expected, rtol=1e-6)
    cx, cy, rx, ry = scene.meta["ellipse"]
    np.testing.assert_array_equal(scene.fg_left, ((x - cx) / rx) ** 2 + ((y - cy) / ry) ** 2 <= 1)


def test_disparity_coefficients():
    theta = disparity_coefficients(10.0, slope=(0.1, -0.2), curvature=(0.01, 0.02, 0.03),
                                   centre=(5.0, 7.0))
    for px, py in [(5.0, 7.0), (0.0, 0.0), (9.0, 2.0)]:
        u, v = px - 5.0, py - 7.0
        want = 10 + 0.1 * u - 0.2 * v + 0.01 * u * u + 0.02 * u * v + 0.03 * v * v
        assert _u(np.array(px), np.array(py)) @ np.array(theta) == pytest.approx(want)


@pytest.mark.parametrize("d_fg, d_bg", [(24.0, 8.0), (20.0, 5.0), (13.5, 6.0)])
def test_occlusion_width_is_the_disparity_jump(d_fg, d_bg):
    """Left of a fronto-parallel foreground, the occluded run is d_fg - d_bg pixels wide."""
    scene = make_scene("easy", d_fg=d_fg, d_bg=d_bg)
    jump = d_fg - d_bg
    rows = 0
    for y in range(scene.fg_left.shape[0]):
        fg_x = np.flatnonzero(scene.fg_left[y])
        if fg_x.size < jump + 2:             # narrow rows: the run detaches from the edge
            continue
        edge = fg_x[0]
        run = 0
        while scene.occ_left[y, edge - 1 - run] and not scene.fg_left[y, edge - 1 - run]:
            run += 1
        assert abs(run - jump) <= 1, (y, run)
        rows += 1
    assert rows > 20
    # No foreground pixel is occluded; the left border strip (x - d_bg < -0.5) is.
    assert not (scene.occ_left & scene.fg_left).any()
    assert scene.occ_left[:, :int(np.ceil(d_bg - 0.5))].all()


def test_ground_truth_fields_and_perfect_score():
    scene = make_scene("tiny")
    h, w = 48, 64
    assert scene.left.shape == scene.right.shape == (h, w, 3)
    assert scene.left.dtype == scene.right.dtype == scene.disp_left.dtype == np.float32
    for key in ("fg_left", "occ_left", "roi_fg", "roi_bg", "boundary"):
        assert getattr(scene, key).shape == (h, w) and getattr(scene, key).dtype == bool
    assert np.isfinite(scene.disp_left).all()
    assert scene.d_max % 2 == 0 and scene.disp_left.max() + 2 <= scene.d_max
    np.testing.assert_array_equal(scene.boundary, boundary_from_foreground(scene.fg_left))
    # The left image is quantised to 8 bits (a PNG round trip is exact).
    np.testing.assert_array_equal(np.round(scene.left * 255) / 255, scene.left)
    # init: the true ellipse shrunk and shifted; cyclopean = left shifted by -d_fg(centre)/2.
    cx, cy, rx, ry = scene.meta["ellipse"]
    ix, iy, irx, iry = scene.init_ellipse
    assert irx < rx and iry < ry and (ix, iy) != (cx, cy)
    assert scene.init_ellipse_cyclopean == pytest.approx((ix - 6.0, iy, irx, iry))
    s = score(scene.disp_left, scene.occ_left, scene)
    assert (s["occ_f1"], s["bad4"]) == (1.0, 0.0) and s["n_true_occ"] > 0


def test_determinism_and_noise():
    a, b = make_scene("tiny", seed=7), make_scene("tiny", seed=7)
    for key in ("left", "right", "disp_left", "occ_left"):
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key))
    assert not np.array_equal(a.left, make_scene("tiny", seed=8).left)
    noisy = make_scene("tiny", seed=7, noise=0.05, quantize=False)
    residual = noisy.left - make_scene("tiny", seed=7, quantize=False).left
    assert 0.03 < residual.std() < 0.06


def test_round_trip_through_folder(tmp_path):
    scene = write_scene(tmp_path / "s", "slanted", seed=2)
    back = load_scene(tmp_path / "s")
    for key in ("left", "right", "disp_left", "fg_left", "occ_left", "roi_fg", "roi_bg",
                "boundary"):
        np.testing.assert_array_equal(getattr(back, key), getattr(scene, key), err_msg=key)
    assert back.d_max == scene.d_max and back.name == scene.name == "slanted_seed2"
    assert back.init_ellipse == pytest.approx(scene.init_ellipse)
    assert back.init_ellipse_cyclopean == pytest.approx(scene.init_ellipse_cyclopean)
    assert back.meta["seed"] == 2 and back.meta["spec"]["noise"] == PRESETS["slanted"]["noise"]


@pytest.mark.parametrize("kwargs, message", [
    ({"preset": "nope"}, "preset: unknown 'nope'"),
    ({"colour": 1}, "unknown parameter"),
    ({"d_fg": 5.0, "d_bg": 8.0}, "foreground must be in front"),
    ({"d_fg": (1, 2)}, "d_fg: expected a number or 6 finite coefficients"),
    ({"d_bg": -1.0}, "d_bg: disparity must be >= 0"),
    ({"d_fg": disparity_coefficients(24.0, slope=(1.0, 0.0))}, "d_fg: d/dx must stay below"),
    ({"ellipse": (500.0, 500.0, 3.0, 3.0)}, "covers no pixel"),
])
def test_errors(kwargs, message):
    preset = kwargs.pop("preset", "easy")
    with pytest.raises(ValueError, match=message):
        make_scene(preset, **kwargs)


#: sha256 of (left, right, disp_left, fg_left, occ_left, roi_fg, roi_bg, boundary) bytes,
#: computed before textures and outlines were added: the presets' pixels must not change.
PRESET_SHA256 = [
    ("easy", 0, {}, "8406edb13dde5b46c914594de14f4fc07be877e99030f8990cb3d1e6fa8f5578"),
    ("slanted", 0, {}, "7238e1ff4282542461ec89d9c3e5422f7d8d703863fa7d1b5a699fe5f4e2a40f"),
    ("tiny", 0, {}, "2e272551390b347eb058e76df0a32777e49d5bc1fec459d9ae2daedcff4f8905"),
    ("tiny", 7, {"noise": 0.05, "quantize": False},
     "0dea8dd6a60bce19b23d61fe49fc25e04c9aaeb73940d54fabed4fb4cb0070a6"),
]


@pytest.mark.parametrize("preset, seed, extra, digest", PRESET_SHA256)
def test_presets_are_unchanged(preset, seed, extra, digest):
    import hashlib
    scene = make_scene(preset, seed=seed, **extra)
    h = hashlib.sha256()
    for key in ("left", "right", "disp_left", "fg_left", "occ_left", "roi_fg", "roi_bg",
                "boundary"):
        h.update(np.ascontiguousarray(getattr(scene, key)).tobytes())
    assert h.hexdigest() == digest
    assert scene.d_max == {"easy": 26.0, "slanted": 26.0, "tiny": 14.0}[preset]


@pytest.mark.parametrize("outline, texture_fg, texture_bg", [
    ("rectangle", {"kind": "stripes", "period": 4.0}, None),
    ("L", {"kind": "palette"}, "palette"),
    ("blob", {"kind": "low_contrast", "amplitude": 0.1}, {"kind": "stripes", "angle": 30.0,
                                                           "mix": 0.3}),
])
def test_outlines_and_textures_keep_the_truth_exact(outline, texture_fg, texture_bg):
    """Integer disparities: every visible left pixel lands on a right pixel of the same colour,
    whatever the outline and the textures; the outline lies in the box of ``ellipse``."""
    scene = make_scene("easy", seed=3, outline=outline, texture_fg=texture_fg,
                       texture_bg=texture_bg, d_max_step=16)
    y, x = _grid(scene)
    xr = x - scene.disp_left.astype(int)
    visible = ~scene.occ_left
    assert (xr[visible] >= 0).all() and not (scene.occ_left & scene.fg_left).any()
    np.testing.assert_allclose(scene.left[visible], scene.right[y[visible], xr[visible]],
                               atol=1e-5)
    cx, cy, rx, ry = scene.meta["ellipse"]
    box = (np.abs(x - cx) <= rx) & (np.abs(y - cy) <= ry)
    assert scene.fg_left.any() and not (scene.fg_left & ~box).any()
    if outline == "rectangle":
        np.testing.assert_array_equal(scene.fg_left, box)
    assert scene.d_max == 32.0 and scene.meta["spec"]["outline"] == outline


def test_stripes_texture_is_periodic_along_x():
    scene = make_scene("easy", texture_bg={"kind": "stripes", "period": 5.0})
    row = scene.left[2].astype(np.float64)                  # a background row
    np.testing.assert_allclose(row[5:], row[:-5], atol=1.5 / 255)
    assert np.abs(row[1:] - row[:-1]).max() > 0.1


@pytest.mark.parametrize("kwargs, message", [
    ({"texture_fg": {"kind": "plaid"}}, "texture_fg: unknown texture kind 'plaid'"),
    ({"texture_bg": {"kind": "stripes", "width": 3}}, "texture_bg: unknown parameter.*width"),
    ({"texture_fg": {"kind": "stripes", "period": 0}}, "stripes need a period > 0"),
    ({"texture_fg": 3}, "texture_fg: expected a dict"),
    ({"texture_bg": "stripy"}, "texture_bg: unknown texture kind 'stripy'"),
    ({"outline": "star"}, "outline: unknown 'star'"),
    ({"d_max_step": 0}, "d_max_step: expected a positive integer"),
])
def test_texture_and_outline_errors(kwargs, message):
    with pytest.raises(ValueError, match=message):
        make_scene("easy", **kwargs)


# ------------------------------------------------------------------------------ props
def test_a_box_behind_the_object_is_seen_and_hidden_as_the_z_buffer_says():
    """A box at 16 px between the object (24 px) and the wall (8 px): integer disparities, so
    every visible left pixel lands on a right pixel of its colour; the object's strip over
    the box is 8 px wide, over the wall 16 px; the box hides 8 px of the wall on its left."""
    box = (41.0, 60.0, 15.0, 20.0)             # x 26..56, y 40..80
    scene = make_scene("easy", seed=2, props=({"d": 16.0, "box": box},), outline="rectangle",
                       ellipse=(80.0, 48.0, 24.0, 30.0))   # x 56..104, y 18..78
    y, x = _grid(scene)
    on_box = (np.abs(x - 41) <= 15) & (np.abs(y - 60) <= 20) & ~scene.fg_left
    np.testing.assert_array_equal(scene.disp_left, np.where(
        scene.fg_left, 24.0, np.where(on_box, 16.0, 8.0)))
    xr = x - scene.disp_left.astype(int)
    visible = ~scene.occ_left
    np.testing.assert_allclose(scene.left[visible], scene.right[y[visible], xr[visible]],
                               atol=1e-5)
    assert np.flatnonzero(scene.occ_left[70, 30:]).tolist() == list(range(18, 26))  # 48..55
    assert np.flatnonzero(scene.occ_left[30, 30:]).tolist() == list(range(10, 26))  # 40..55
    # the box's strip on the wall, after the wall's own strip at the left border (x - 8 < 0)
    assert np.flatnonzero(scene.occ_left[50, :30]).tolist() == list(range(8)) + list(range(18, 26))
    s = score(scene.disp_left, scene.occ_left, scene)
    assert (s["occ_f1"], s["bad4"]) == (1.0, 0.0)


def test_a_floor_meets_the_wall_where_it_comes_nearer():
    floor = {"d": disparity_coefficients(8.0, slope=(0.0, 0.25), centre=(0.0, 60.0)),
             "box": None}                        # 8 px at row 60, 17 px at the bottom
    scene = make_scene("easy", seed=1, props=(floor,), ellipse=(64.0, 30.0, 20.0, 16.0))
    y, x = _grid(scene)
    want = np.where(scene.fg_left, 24.0, np.maximum(8.0, 8.0 + 0.25 * (y - 60.0)))
    np.testing.assert_allclose(scene.disp_left, want, atol=1e-5)
    assert scene.d_max == 26.0                  # the object is still the nearest
    s = score(scene.disp_left, scene.occ_left, scene)
    assert (s["occ_f1"], s["bad4"]) == (1.0, 0.0)


@pytest.mark.parametrize("props, message", [
    (({"d": 30.0, "box": (64.0, 48.0, 10.0, 10.0)},),
     r"d_fg, props\[0\]: d: the foreground must be in front of the prop \(props\[0\]\)"),
    (({"d": 10.0, "colour": 1},), r"props\[0\]: unknown key\(s\) colour"),
    (({"box": None},), r"props\[0\]: expected a dict with 'd'"),
    (({"d": 10.0, "box": (1.0, 2.0, 0.0, 3.0)},), r"props\[0\]: box: expected \(cx, cy, rx, ry\)"),
    (({"d": 10.0, "outline": "star"},), r"props\[0\]: outline: unknown 'star'"),
    (({"d": -3.0, "box": (20.0, 20.0, 5.0, 5.0)},), r"props\[0\]: d: disparity must be >= 0"),
    (({"d": 12.0, "box": (20.0, 20.0, 5.0, 5.0)}, {"d": 40.0, "box": (105.0, 48.0, 5.0, 10.0)}),
     r"props\[1\]: nearer than the object on its right-view rays, it hides \d+ of its pixels"),
])
def test_prop_errors_name_the_prop(props, message):
    with pytest.raises(ValueError, match=message):
        make_scene("easy", props=props)


# ------------------------------------------------------------------------------ several objects
def _rect(cx, cy, rx, ry, angle=0.0):
    """The outline test of a turned rectangle, written out: ``|u|, |v| <= 1`` in its frame."""
    a = np.radians(angle)

    def inside(x, y):
        u = (np.cos(a) * (x - cx) + np.sin(a) * (y - cy)) / rx
        v = (np.cos(a) * (y - cy) - np.sin(a) * (x - cx)) / ry
        return (np.abs(u) <= 1) & (np.abs(v) <= 1)
    return inside


def _ellipse(cx, cy, rx, ry):
    return lambda x, y: ((x - cx) / rx) ** 2 + ((y - cy) / ry) ** 2 <= 1


#: A slanted and curved scene of a wall and four objects: a box behind, the clicked ellipse, a
#: turned rod before it and a box before its lower right; ``(coefficients, outline test)``.
_WALL = disparity_coefficients(6.0, slope=(-0.02, 0.01), curvature=(-0.0004, 0.0, 0.0),
                               centre=(48.0, 36.0))
_OBJECTS = (
    ({"d": disparity_coefficients(11.3, slope=(0.03, 0.0), centre=(22.7, 30.2)),
      "box": (22.7, 30.2, 14.1, 18.3), "name": "box behind"}, _rect(22.7, 30.2, 14.1, 18.3)),
    ({"d": disparity_coefficients(17.6, slope=(0.05, -0.02), curvature=(-0.002, 0.0, -0.001),
                                  centre=(50.4, 35.1)),
      "box": (50.4, 35.1, 20.3, 17.2), "outline": "ellipse", "name": "ellipse"},
     _ellipse(50.4, 35.1, 20.3, 17.2)),
    ({"d": 25.7, "box": (47.1, 33.3, 60.2, 2.1), "angle": 28.0, "name": "rod"},
     _rect(47.1, 33.3, 60.2, 2.1, 28.0)),
    ({"d": disparity_coefficients(22.2, slope=(-0.04, 0.0), centre=(70.3, 49.9)),
      "box": (70.3, 49.9, 9.4, 8.1), "name": "front box"}, _rect(70.3, 49.9, 9.4, 8.1)),
)


def _slanted_multi(**extra):
    return make_multi_scene(width=96, height=72, d_bg=_WALL, objects=[o for o, _ in _OBJECTS],
                            clicked=1, seed=5, **extra)


def _root(theta, xr, y, lo, hi):
    """Left-view x of ``x - d(x, y) = xr`` by bisection (``x - d`` increases along x)."""
    lo, hi = np.full_like(xr, lo), np.full_like(xr, hi)
    for _ in range(80):
        mid = (lo + hi) / 2
        right = mid - (_u(mid, y) @ theta) > xr
        lo, hi = np.where(right, lo, mid), np.where(right, mid, hi)
    return (lo + hi) / 2


def test_several_objects_follow_a_numpy_ray_cast():
    """Left view: each pixel sees the nearest surface holding it.  Occlusion: a left pixel is
    hidden exactly when its right-view ray, solved here by bisection, meets a nearer surface,
    or leaves the image."""
    scene = _slanted_multi()
    y, x = _grid(scene)
    x, y = x.astype(np.float64), y.astype(np.float64)
    thetas = [np.array(_WALL)] + [np.array(o["d"]) if np.ndim(o["d"]) else
                                  np.array([0, 0, 0, 0, 0, o["d"]]) for o, _ in _OBJECTS]
    covers = [lambda x, y: np.ones(np.shape(x), bool)] + [inside for _, inside in _OBJECTS]
    d = np.stack([np.where(c(x, y), _u(x, y) @ t, -np.inf) for t, c in zip(thetas, covers)])
    np.testing.assert_array_equal(scene.layers_left, d.argmax(0))
    np.testing.assert_allclose(scene.disp_left, d.max(0), rtol=1e-6)
    assert set(np.unique(scene.layers_left)) == {0, 1, 2, 3, 4}

    d_left = scene.disp_left.astype(np.float64)
    xr = x - d_left
    hidden = xr < -0.5
    for k, (theta, inside) in enumerate(zip(thetas, covers)):
        xk = _root(theta, xr, y, -60.0, 160.0)
        dk = _u(xk, y) @ theta
        hidden |= (scene.layers_left != k) & inside(xk, y) & (dk > d_left + 1e-6)
    np.testing.assert_array_equal(scene.occ_left, hidden)
    assert (scene.occ_left & (scene.layers_left == 2)).any()   # the rod hides some of the ellipse


def test_several_objects_keep_colours_exact():
    """Integer disparities, no noise: a left pixel not occluded has the colour of the right
    pixel at x - d, whatever object it shows; an occluded one (not at the border) does not."""
    scene = make_multi_scene(width=128, height=96, d_bg=6.0, seed=2, objects=[
        {"d": 12.0, "box": (30.0, 60.0, 14.0, 20.0), "texture": "palette"},
        {"d": 20.0, "box": (64.0, 48.0, 24.0, 20.0), "outline": "blob"},
        {"d": 28.0, "box": (64.0, 48.0, 70.0, 2.5), "angle": -20.0, "texture": "stripes"},
        {"d": 26.0, "box": (88.0, 66.0, 12.0, 10.0), "outline": "ellipse"}], clicked=1)
    y, x = _grid(scene)
    xr = x - scene.disp_left.astype(int)
    visible = ~scene.occ_left
    assert (xr[visible] >= 0).all() and visible.mean() > 0.7
    np.testing.assert_allclose(scene.left[visible], scene.right[y[visible], xr[visible]],
                               atol=1e-5)
    inner = scene.occ_left & (xr >= 0)
    assert np.abs(scene.left[inner] - scene.right[y[inner], xr[inner]]).max(-1).min() > 0
    assert set(np.unique(scene.layers_left)) == {0, 1, 2, 3, 4}


def test_the_band_is_the_clicked_objects_own():
    """The clicked object at 20 px (x 31..60) with a box at 30 px before its right side (x
    57..86, rows 22..42) over a wall at 4 px: in those rows its own boundary is its left edge
    only, the band leaves out the box and the 10 px the box hides of the object, and keeps
    the object's own 16 px occlusion strip; elsewhere both edges are its own."""
    scene = make_multi_scene(width=128, height=64, d_bg=4.0, seed=1, objects=[
        {"d": 20.0, "box": (45.3, 32.0, 15.0, 20.0), "name": "clicked"},
        {"d": 30.0, "box": (71.3, 32.0, 15.0, 10.0), "name": "front box"}], clicked=0)
    cols = lambda mask: np.flatnonzero(mask).tolist()
    r = lambda a, b: list(range(a, b + 1))
    assert cols(scene.layers_left[30] == 1) == r(31, 56)
    assert cols(scene.layers_left[30] == 2) == r(57, 86)
    np.testing.assert_array_equal(scene.fg_left, scene.layers_left == 1)
    assert cols(scene.occ_left[30]) == r(0, 3) + r(15, 30) + r(47, 56)
    assert cols(scene.boundary[30]) == [31] and cols(scene.boundary[15]) == [31, 60]
    assert cols(scene.roi_fg[30]) == r(31, 46) and cols(scene.roi_bg[30]) == r(11, 30)
    assert cols(scene.roi_fg[15]) == r(31, 60) and cols(scene.roi_bg[15]) == r(11, 30) + r(61, 80)
    assert not ((scene.roi_fg | scene.roi_bg) & (scene.layers_left == 2)).any()
    s = score(scene.disp_left, scene.occ_left, scene)
    # 41 rows of the strip x 15..30, less x 30 beside the boundary (not scored)
    assert (s["occ_f1"], s["bad4"], s["n_true_occ"]) == (1.0, 0.0, 41 * 15)
    x, y = (int(v) for v in scene.init_point)      # deep inside its part both cameras see
    assert (scene.fg_left & ~scene.occ_left)[y - 7:y + 8, x - 7:x + 8].all()


def test_scoring_reads_the_clicked_objects_band_from_the_folder(tmp_path):
    """``roi_fg.png`` / ``roi_bg.png`` carry the rule: a prediction that is wrong only on the
    box before the object (its depth, and occlusion all over it) scores perfectly from the
    folder, and not with the band recomputed from ``fg_left`` alone."""
    import dataclasses
    write_multi_scene(tmp_path / "s", seed=1, width=128, height=64, d_bg=4.0, objects=[
        {"d": 20.0, "box": (45.3, 32.0, 15.0, 20.0)},
        {"d": 30.0, "box": (71.3, 32.0, 15.0, 10.0)}], clicked=0)
    scene = load_scene(tmp_path / "s")
    front = scene.layers_left == 2
    disparity = np.where(front, 4.0, scene.disp_left)
    occlusion = scene.occ_left | front
    s = score(disparity, occlusion, scene)
    assert (s["occ_f1"], s["bad4"]) == (1.0, 0.0)
    s = score(disparity, occlusion, dataclasses.replace(scene, roi_fg=None, roi_bg=None))
    assert s["occ_f1"] < 0.9 and s["bad4"] > 10


def test_one_object_gives_the_two_layer_truth():
    """With one object before a wall, the object's band is the paper's band and the truth is
    the two-layer scene's (only the textures are drawn in another order)."""
    two = make_scene("slanted", outline="L", ellipse=(60.0, 50.0, 30.0, 28.0))
    theta_fg, theta_bg = two.meta["theta_fg"], two.meta["theta_bg"]
    multi = make_multi_scene(width=128, height=96, d_bg=theta_bg, objects=[
        {"d": theta_fg, "box": (60.0, 50.0, 30.0, 28.0), "outline": "L"}], d_max_step=2)
    for key in ("disp_left", "occ_left", "fg_left", "roi_fg", "roi_bg", "boundary"):
        np.testing.assert_array_equal(getattr(multi, key), getattr(two, key), err_msg=key)
    assert multi.d_max == two.d_max
    np.testing.assert_array_equal(multi.layers_left, two.fg_left.astype(np.uint8))


def test_a_multi_scene_folder_round_trips_and_starts_from_its_click(tmp_path):
    from lss_kernels.apps.jobs import scene_init
    from lss_kernels.model.init import Point
    scene = write_multi_scene(tmp_path / "m", name="m", meta={"family": "test"},
                              **{"width": 96, "height": 72, "d_bg": _WALL, "clicked": 1,
                                 "objects": [o for o, _ in _OBJECTS], "seed": 5})
    back = load_scene(tmp_path / "m")
    assert back.init_ellipse is None and back.init_point == scene.init_point
    np.testing.assert_array_equal(back.layers_left, scene.layers_left)
    assert back.layers_left.dtype == np.uint8
    for key in ("fg_left", "occ_left", "roi_fg", "roi_bg", "boundary"):
        np.testing.assert_array_equal(getattr(back, key), getattr(scene, key))
    assert back.meta["family"] == "test" and back.meta["clicked"] == 1
    assert [o["name"] for o in back.meta["objects"]] == [o["name"] for o, _ in _OBJECTS]
    assert scene_init(back) == (Point(*scene.init_point), "left")


def test_multi_scenes_are_deterministic():
    a, b, c = _slanted_multi(noise=0.01), _slanted_multi(noise=0.01), _slanted_multi()
    np.testing.assert_array_equal(a.left, b.left)
    assert np.abs(a.left - c.left).max() > 0


@pytest.mark.parametrize("extra, message", [
    ({"clicked": 4}, r"clicked: expected an index in objects \(0..3\), got 4"),
    ({"init_point": (2.0, 2.0)}, "init_point: expected .* on a visible pixel"),
    ({"d_max": 20.0}, r"d_max: expected at least max\(disp_left\) \+ 2"),
    ({"colour": 1}, "make_multi_scene: unknown parameter"),
    ({"objects": ()}, "objects: expected at least one object"),
    ({"objects": ({"d": 5.0, "box": (10.0, 10.0, 3.0, 3.0), "angle": "x"},), "clicked": 0},
     r"objects\[0\]: angle: expected a finite number"),
    ({"objects": ({"d": 5.0, "box": (48.0, 36.0, 8.0, 8.0)},
                  {"d": 9.0, "box": (48.0, 36.0, 9.0, 9.0)}), "clicked": 0},
     r"clicked: objects\[0\] is hidden"),
])
def test_multi_errors(extra, message):
    params = {"width": 96, "height": 72, "d_bg": _WALL, "clicked": 1,
              "objects": [o for o, _ in _OBJECTS], **extra}
    with pytest.raises(ValueError, match=message):
        make_multi_scene(**params)


def test_a_bad_click_or_layer_map_in_a_folder_is_named(tmp_path):
    import json

    from lss_kernels.io import write_png
    write_multi_scene(tmp_path / "s", seed=1, width=48, height=32, d_bg=4.0, objects=[
        {"d": 10.0, "box": (24.0, 16.0, 10.0, 8.0)}])
    meta = json.loads((tmp_path / "s" / "meta.json").read_text())
    (tmp_path / "s" / "meta.json").write_text(json.dumps({**meta, "init_point": [3, "x"]}))
    with pytest.raises(ValueError, match=r"init_point: expected \[x, y\]"):
        load_scene(tmp_path / "s")
    (tmp_path / "s" / "meta.json").write_text(json.dumps(meta))
    write_png(tmp_path / "s" / "layers_left.png", np.zeros((32, 48, 3), np.uint8))
    with pytest.raises(ValueError, match="layers_left.png: expected an 8-bit gray image"):
        load_scene(tmp_path / "s")
