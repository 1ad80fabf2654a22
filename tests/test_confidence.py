"""The confidence map and its judge: each factor of :func:`lss_kernels.confidence.confidence`
on hand-made maps, the boundary distance against a brute-force one, and sparsification and
the 10 % / 50 % ratio on hand-counted cases."""
import numpy as np
import pytest

from lss_kernels.confidence import (BOUNDARY_REACH, boundary_distance, confidence,
                                    confidence_ratio, local_stability, sparsification)


def test_boundary_distance_against_brute_force():
    rng = np.random.default_rng(3)
    fg = np.zeros((20, 30), bool)
    fg[5:14, 8:20] = True
    fg[rng.random(fg.shape) < 0.02] ^= True
    got = boundary_distance(fg)
    ys, xs = np.mgrid[0:20, 0:30]
    padded = np.pad(fg, 1, mode="edge")
    touches = np.zeros_like(fg)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            touches |= padded[1 + dy:21 + dy, 1 + dx:31 + dx] != fg
    assert (got[touches] == 0).all()
    ty, tx = np.nonzero(touches)
    euclid = np.sqrt((ys[..., None] - ty) ** 2 + (xs[..., None] - tx) ** 2).min(axis=2)
    # chamfer with steps 1 and sqrt 2: at least the Euclidean distance, at most 8 % above
    assert (got >= euclid - 1e-9).all()
    assert (got <= 1.0824 * euclid + 1e-9).all()


def test_one_layer_has_no_boundary():
    assert (boundary_distance(np.ones((5, 6), bool)) == BOUNDARY_REACH).all()


def test_local_stability_is_the_share_of_distinct_matches_around():
    distinct = np.zeros((9, 9), bool)
    distinct[:, :3] = True
    s = local_stability(distinct, radius=1)
    assert s[4, 0] == 1.0 and s[4, 1] == 1.0
    assert s[4, 3] == pytest.approx(1 / 3) and s[4, 6] == 0.0
    assert s[0, 3] == pytest.approx(1 / 3)           # the window clamped to the image


def _flat_two_layers(H=16, W=32):
    fg = np.zeros((H, W), bool)
    fg[:, W // 2:] = True
    disparity = np.where(fg, 20.0, 5.0)
    return fg, disparity


def test_each_factor_lowers_the_confidence():
    fg, d = _flat_two_layers()
    occ = np.zeros_like(fg)
    occ[:, 12:16] = True
    ratio = np.full(fg.shape, 0.5)
    ratio[2, 2] = 0.95                                # a weak match
    distinct = ratio < 0.9
    match = d.copy()
    match[4, 4] = d[4, 4] + 3.0                       # a match that disagrees
    c = confidence(d, fg, occ, match, ratio, distinct)
    assert c.dtype == np.float32 and c.shape == fg.shape
    assert (c[occ] == 0).all()
    far = c[10, 2]                                    # far from the boundary, all agree
    assert far == pytest.approx(0.5, abs=1e-3)        # 1 - peak ratio, nothing else
    assert c[2, 2] == pytest.approx(0.05, abs=1e-3)
    assert c[4, 4] == pytest.approx(0.5 * np.exp(-3.0), abs=1e-3)
    # nearer the boundary (column 16) less sure, rising with the distance
    row = c[8, 16:]
    assert (np.diff(row[:8]) > 0).all() and row[0] < 0.7 * far
    # the same boundary amid pixels without distinct matches: less sure still
    weak = confidence(d, fg, occ, match, np.full(fg.shape, 0.5), np.zeros_like(fg))
    assert weak[8, 17] < c[8, 17]


def test_sparsification_counts_by_hand():
    conf = np.array([0.9, 0.8, 0.7, 0.6, 0.5, 0.4, 0.3, 0.2, 0.1, 0.0])
    bad = np.array([0, 0, 0, 0, 0, 1, 0, 1, 1, 1], bool)
    fractions, rates = sparsification(conf, bad, [0.1, 0.5, 0.6, 1.0])
    np.testing.assert_allclose(rates, [0.0, 0.0, 100 / 6, 40.0])
    ratio, worst, best = confidence_ratio(conf, bad)
    assert (worst, best) == (100.0, 0.0) and ratio == np.inf
    # a confidence that knows nothing: both ends alike
    ratio, worst, best = confidence_ratio(np.zeros(10), np.tile([True, False], 5))
    assert (worst, best) == (0.0, 60.0) and ratio == 0.0
    with pytest.raises(ValueError, match=r"^fractions: expected values in \(0, 1\]"):
        sparsification(conf, bad, [0.0])


def test_a_periodic_image_lowers_the_confidence():
    from lss_kernels.confidence import periodic_map
    from lss_kernels.checks.periodicity import TILE
    H, W = 2 * TILE[0] + 5, 2 * TILE[1] + 40
    x = np.arange(W)
    rng = np.random.default_rng(0)
    image = np.repeat(rng.random((H, W))[..., None], 3, axis=2)
    image[:, :W // 2] = (0.5 + 0.4 * np.sin(2 * np.pi * x[:W // 2] / 6.0))[None, :, None]
    periodic = periodic_map(image)
    assert periodic.shape == (H, W)
    assert periodic[:, :TILE[1]].min() > 0.6 and periodic[:, -1].max() < 0.3
    fg, d = _flat_two_layers(H, W)
    ones, none = np.ones((H, W), bool), np.zeros((H, W), bool)
    plain = confidence(d, fg, none, d, np.full((H, W), 0.2), ones)
    c = confidence(d, fg, none, d, np.full((H, W), 0.2), ones, periodic)
    np.testing.assert_allclose(c, plain * (1 - periodic), rtol=1e-5, atol=1e-7)
    assert c[5, 5] < 0.4 * c[5, W - 5]


def test_a_solve_without_the_refinement_has_no_match_evidence(ti_arch):
    """Params(refine=False) (a periodic pair's first solve): the confidence is the boundary
    factor amid no distinct matches times the periodic one, 0 on occluded pixels."""
    from lss_kernels import Params, solve
    from lss_kernels.confidence import periodic_map
    from lss_kernels.scenes import make_scene
    scene = make_scene("tiny")
    result = solve(scene.left, scene.right, scene.d_max, tuple(scene.init_ellipse),
                   params=Params(refine=False))
    none = np.zeros(result.foreground.shape, bool)
    want = confidence(result.disparity, result.foreground, result.occlusion, result.disparity,
                      np.zeros(none.shape), none, periodic_map(scene.left))
    np.testing.assert_array_equal(result.confidence, want)
    assert (result.confidence[result.occlusion] == 0).all() and result.confidence.max() > 0.5
