"""Each kernel against its small, readable numpy reference (lss_kernels.reference.kernels)."""
import numpy as np
import pytest
import taichi as ti

from lss_kernels.reference import kernels as ref
from lss_kernels.kernels.backend import FieldPool
from lss_kernels.model.matching import MatchingCost
from lss_kernels.model.messages import Messages
from lss_kernels.params import BOUNDARY_CLIP, CURVATURE_CLIP, CURVATURE_SIGMA, Params

H, W, C = 22, 34, 7
SIZES = (3, 9, 18)


def _field(pool_arrays):
    """Allocate and fill (H, W) f32 fields from numpy arrays."""
    pool = FieldPool()
    fields = [pool.field(ti.f32, a.shape) for a in pool_arrays]
    pool.finalize()
    for f, a in zip(fields, pool_arrays):
        f.from_numpy(a.astype(np.float32))
    return pool, fields


@pytest.fixture(scope="module")
def pair(ti_arch):
    rng = np.random.default_rng(3)
    left = rng.random((H, W, 3)).astype(np.float32)
    right = rng.random((H, W, 3)).astype(np.float32)
    return left, right


@pytest.fixture(scope="module")
def hierarchy(pair):
    from lss_kernels.model.hierarchy import PatchHierarchy
    pool = FieldPool()
    h = PatchHierarchy(pool, H, W, C, SIZES)
    matcher = MatchingCost(pool, H, W)
    lf, rf = pool.vector(3, ti.f32, (H, W)), pool.vector(3, ti.f32, (H, W))
    pool.finalize()
    lf.from_numpy(pair[0])
    rf.from_numpy(pair[1])
    h.build_costs(matcher, lf, rf)
    h.messages = Messages(h)        # one message pass (one compiled kernel) per hierarchy
    yield h
    pool.destroy()


def _plane(field):
    """The image's ``(H, W)`` corner of a plane of the size bucket's shape."""
    return field.to_numpy()[:H, :W]


def _inside(h, field, level):
    m = h.levels[level].margin
    return field.to_numpy()[m:m + H, m:m + W]


def test_level_geometry_children_tile_the_parent():
    from lss_kernels.model.hierarchy import level_geometry
    for lev, child in zip(level_geometry(SIZES), (1,) + SIZES):
        covered = sorted(o - child // 2 + i for o in lev.offsets for i in range(child))
        assert covered == list(range(-(lev.size // 2), -(lev.size // 2) + lev.size))


def test_patch_costs_match_box_means(pair, hierarchy):
    want = ref.patch_costs(pair[0].astype(np.float64), pair[1].astype(np.float64), C, SIZES)
    for level in range(len(SIZES)):
        got = _inside(hierarchy, hierarchy.levels[level].cost, level)
        np.testing.assert_allclose(got, want[level], atol=2e-5)
        assert got.min() == pytest.approx(0.0, abs=1e-6)
        assert got.max() == pytest.approx(1.0, abs=1e-6)


def test_ad_census_patch_costs_match_the_specification(pair, ti_arch):
    from lss_kernels.model.hierarchy import PatchHierarchy
    pool = FieldPool()
    h = PatchHierarchy(pool, H, W, C, SIZES)
    matcher = MatchingCost(pool, H, W, "ad_census")
    lf, rf = pool.vector(3, ti.f32, (H, W)), pool.vector(3, ti.f32, (H, W))
    pool.finalize()
    # grey levels on a coarse grid: no near-ties between float32 and float64 comparisons
    left, right = (np.round(p * 16) / 16 for p in pair)
    lf.from_numpy(left.astype(np.float32))
    rf.from_numpy(right.astype(np.float32))
    matcher.setup(lf, rf)
    h.build_costs(matcher, lf, rf)
    want = ref.patch_costs(left.astype(np.float64), right.astype(np.float64), C, SIZES,
                           kind="ad_census")
    plain = ref.patch_costs(left.astype(np.float64), right.astype(np.float64), C, SIZES)
    for level in range(len(SIZES)):
        got = _inside(h, h.levels[level].cost, level)
        np.testing.assert_allclose(got, want[level], atol=1e-4)
        assert np.abs(got - plain[level]).max() > 0.05     # not the AD cost
    pool.destroy()


def _smooth_phi(rng, shift=0.0):
    y, x = np.mgrid[0:H, 0:W]
    return ((12.0 - np.hypot(x - 17 - shift, (y - 11) * 1.3)) / 10.0
            + 0.05 * rng.standard_normal((H, W)))


def test_upward_sums_and_extremes_match_brute_force(hierarchy):
    rng = np.random.default_rng(4)
    D = rng.random((H, W)) * C
    phi, phi_plus = _smooth_phi(rng), _smooth_phi(rng, 3.0)
    pool, (fD, fphi, fplus) = _field([D, phi, phi_plus])
    hierarchy.upward(fD, fphi, fplus)
    for level, s in enumerate(SIZES):
        np.testing.assert_allclose(hierarchy.levels[level].image(hierarchy.levels[level].d_sum),
                                   ref.box_sum(D, s), rtol=1e-5, atol=1e-3)
        np.testing.assert_allclose(hierarchy.levels[level].image(hierarchy.levels[level].phi_max),
                                   ref.box_extreme(phi.astype(np.float32), s, np.max))
        np.testing.assert_allclose(hierarchy.levels[level].image(hierarchy.levels[level].phi_plus_min),
                                   ref.box_extreme(phi_plus.astype(np.float32), s, np.min))
    pool.destroy()


def test_column_spans_cover_every_reach_in_whole_blocks():
    from lss_kernels.model.hierarchy import column_spans, level_geometry
    levels = level_geometry(SIZES)
    # one pixel per block: exactly the levels' margins
    assert column_spans(levels, W, 1) == [(lev.margin, W + lev.margin) for lev in levels]
    spans = column_spans(levels, W, 8)
    assert spans[-1] == (0, 40)                     # the top level: the image's 5 blocks
    for (left, right), lev in zip(spans, levels):
        assert left % 8 == 0 and right % 8 == 0
        assert left >= lev.margin and right >= W + lev.margin
    for i in range(len(levels) - 1):               # a parent's children stay inside
        reach = max(abs(o) for o in levels[i + 1].offsets)
        assert spans[i][0] >= spans[i + 1][0] + reach
        assert spans[i][1] >= spans[i + 1][1] + reach
    reach = max(abs(o) for o in levels[0].offsets)  # and the pixels' blocks read level 1
    assert spans[0][0] >= reach and spans[0][1] >= 40 + reach


def test_hierarchy_in_one_pixel_blocks_matches_eight(pair, monkeypatch):
    """The upward pass, the messages and the consensus with blocks of one patch centre (the
    GPUs' layout) give what the CPU's blocks of 8 give (W = 34 ends in a partial block): the
    extremes and validity exactly, the sums to float rounding (LLVM may associate a sum of
    lanes differently from a scalar one).  The blocks of 8 are checked against the
    reference in the tests around."""
    from lss_kernels.kernels import lanes as lanes_module
    from lss_kernels.model.hierarchy import PatchHierarchy
    rng = np.random.default_rng(9)
    D = rng.random((H, W)) * C
    phi, phi_plus = _smooth_phi(rng), _smooth_phi(rng, 4.0)
    results = []
    for lanes in (8, 1):
        monkeypatch.setattr(lanes_module, "lanes_for_arch", lambda: lanes)
        pool = FieldPool()
        h = PatchHierarchy(pool, H, W, C, SIZES)
        matcher = MatchingCost(pool, H, W)
        lf, rf = pool.vector(3, ti.f32, (H, W)), pool.vector(3, ti.f32, (H, W))
        fD, fphi, fplus = (pool.field(ti.f32, (H, W)) for _ in range(3))
        pool.finalize()
        assert h.lanes == lanes
        lf.from_numpy(pair[0])
        rf.from_numpy(pair[1])
        for f, a in zip((fD, fphi, fplus), (D, phi, phi_plus)):
            f.from_numpy(a.astype(np.float32))
        h.build_costs(matcher, lf, rf)
        out = {}
        messages = Messages(h)
        for it in range(2):             # the second pass reuses the cached candidates
            h.upward(fD, fphi, fplus)
            messages.run(0.4 / C, True, True, keep=True)
            h.downward()
        for level in range(len(SIZES)):
            for name in ("d_sum", "phi_max", "phi_plus_min", "relay_a", "relay_b"):
                out[name, level] = h.levels[level].image(getattr(h.levels[level], name))
            for name in ("d_p", "sigma_p", "valid"):
                out[name, level] = _plane(getattr(h.levels[level], name))
        out["precision"] = h.extent.image(h.precision)
        out["consensus_mean"] = h.extent.image(h.consensus_mean)
        results.append(out)
        pool.destroy()
    eight, one = results
    assert (eight["precision"] > 0).mean() > 0.5   # most pixels see a valid patch
    for key in eight:
        name = key[0] if isinstance(key, tuple) else key
        if name in ("phi_max", "phi_plus_min", "valid"):
            np.testing.assert_array_equal(one[key], eight[key], err_msg=str(key))
        elif name == "d_p":             # a rounding step may tip a near-tie of Eq. 5
            assert np.isclose(one[key], eight[key], rtol=0, atol=1e-4).mean() > 0.99, key
        else:
            np.testing.assert_allclose(one[key], eight[key], rtol=2e-5, atol=1e-6,
                                       err_msg=str(key))


def test_messages_validity_and_consensus_match_reference(hierarchy):
    rng = np.random.default_rng(5)
    D = rng.random((H, W)) * C
    phi, phi_plus = _smooth_phi(rng), _smooth_phi(rng, 4.0)
    pool, (fD, fphi, fplus) = _field([D, phi, phi_plus])
    hierarchy.upward(fD, fphi, fplus)
    beta = 0.4 / C
    hierarchy.messages.run(beta, True, True, keep=True)
    d_ps, sig_ps, valids = [], [], []
    for level, s in enumerate(SIZES):
        cost = _inside(hierarchy, hierarchy.levels[level].cost, level).astype(np.float64)
        d_mean = ref.box_mean(D.astype(np.float32), s)
        # Eq. 4: valid = (max phi > 0) XOR (min phi(x + delta_theta) < 0)
        valid = (ref.box_extreme(phi.astype(np.float32), s, np.max) > 0) != \
            (ref.box_extreme(phi_plus.astype(np.float32), s, np.min) < 0)
        np.testing.assert_array_equal(_plane(hierarchy.levels[level].valid).astype(bool), valid)
        d_p, sigma_p = ref.patch_messages(cost, d_mean, beta, subpixel=True)
        got_d = _plane(hierarchy.levels[level].d_p)
        got_s = _plane(hierarchy.levels[level].sigma_p)
        assert valid.any() or s == max(SIZES)   # the largest patches may all straddle it
        if valid.any():
            same = valid & np.isclose(got_d, d_p, rtol=0, atol=1e-4)
            assert same.sum() > 0.99 * valid.sum()  # float32 ties may differ
            np.testing.assert_allclose(got_s[same], sigma_p[same], rtol=1e-4)
        d_ps.append(np.where(valid, got_d, 0.0))
        sig_ps.append(np.where(valid, got_s, 1.0))
        valids.append(valid)
    hierarchy.downward()
    prec, mean = ref.consensus(d_ps, sig_ps, valids, SIZES)
    np.testing.assert_allclose(hierarchy.extent.image(hierarchy.precision), prec, rtol=1e-4,
                               atol=1e-12)
    np.testing.assert_allclose(hierarchy.extent.image(hierarchy.consensus_mean), mean, rtol=1e-4,
                               atol=1e-4)
    pool.destroy()


@pytest.mark.parametrize("d_value", [0.0, 1.0, 3.0, 3.5, float(C), "random-integers"])
def test_candidate_messages_match_scan_at_integer_and_extreme_means(hierarchy, d_value):
    """The two-candidate messages equal the full scan of Eq. 5 where the prior mean sits on
    an integer candidate, below the first one (0) and on the last one (c_max)."""
    rng = np.random.default_rng(8)
    if d_value == "random-integers":
        D = rng.integers(0, C + 1, size=(H, W)).astype(np.float64)
    else:
        D = np.full((H, W), d_value)
    ones = np.ones((H, W))
    pool, (fD, fphi, fplus) = _field([D, ones, ones])   # fg and occluded everywhere: valid
    hierarchy.upward(fD, fphi, fplus)
    beta = 0.4 * 3 / C    # a strong prior, so that it moves many argmins
    hierarchy.messages.run(beta, True, True, keep=True)
    for level, s in enumerate(SIZES):
        assert _plane(hierarchy.levels[level].valid).all()
        cost = _inside(hierarchy, hierarchy.levels[level].cost, level).astype(np.float64)
        d_p, sigma_p = ref.patch_messages(cost, ref.box_mean(D.astype(np.float32), s), beta,
                                          subpixel=True)
        got_d = _plane(hierarchy.levels[level].d_p)
        same = np.isclose(got_d, d_p, rtol=0, atol=1e-4)
        assert same.mean() > 0.99
        np.testing.assert_allclose(_plane(hierarchy.levels[level].sigma_p)[same], sigma_p[same],
                                   rtol=1e-4)
    pool.destroy()


def test_cached_candidates_follow_a_moving_prior_mean(hierarchy):
    """Messages computed once, then D moves on part of the image (across integer candidates
    there, within one step elsewhere): every patch still gets the full scan's message, and
    a change of beta drops the cache."""
    rng = np.random.default_rng(21)
    ones = np.ones((H, W))
    D0 = rng.random((H, W)) * C
    D1 = D0.copy()
    D1[:, : W // 2] = np.clip(D1[:, : W // 2] + rng.uniform(-3, 3, (H, W // 2)), 0, C)
    D1[:, W // 2:] = np.floor(D0[:, W // 2:]) + 0.5 * (D0[:, W // 2:] % 1.0)
    for beta in (0.4 / C, 0.4 / C, 1.2 / C):
        for D in (D0, D1):
            pool, (fD, fphi, fplus) = _field([D, ones, ones])
            hierarchy.upward(fD, fphi, fplus)
            hierarchy.messages.run(beta, True, True, keep=True)
            for level, s in enumerate(SIZES):
                cost = _inside(hierarchy, hierarchy.levels[level].cost, level).astype(np.float64)
                want, sigma = ref.patch_messages(cost, ref.box_mean(D.astype(np.float32), s),
                                                 beta, subpixel=True)
                got = _plane(hierarchy.levels[level].d_p)
                same = np.isclose(got, want, rtol=0, atol=1e-4)
                assert same.mean() > 0.99, (beta, level, same.mean())
                np.testing.assert_allclose(_plane(hierarchy.levels[level].sigma_p)[same],
                                           sigma[same], rtol=1e-4)
            pool.destroy()


def test_first_iteration_messages_ignore_prior_and_validity(hierarchy):
    rng = np.random.default_rng(6)
    pool, (fD, fphi, fplus) = _field([rng.random((H, W)) * C, -np.ones((H, W)),
                                      np.ones((H, W))])
    hierarchy.upward(fD, fphi, fplus)   # every patch would be invalid under Eq. 4
    hierarchy.messages.run(10.0, False, False, keep=True)
    with pytest.raises(ValueError, match="validity needs the prior"):
        hierarchy.messages.run(10.0, False, True, keep=True)
    for level in range(len(SIZES)):
        assert _plane(hierarchy.levels[level].valid).all()
        cost = _inside(hierarchy, hierarchy.levels[level].cost, level).astype(np.float64)
        want, _ = ref.patch_messages(cost, np.zeros((H, W)), 0.0, subpixel=True)
        np.testing.assert_allclose(_plane(hierarchy.levels[level].d_p), want, atol=1e-4)
        assert np.abs(want - (cost.argmin(2) + 1)).max() <= 0.5
        assert (want != np.round(want)).mean() > 0.5     # refined below the integer grid
    pool.destroy()


def test_cached_candidates_are_dropped_when_the_costs_change(pair):
    """Same beta, new image pair: the cached candidates must not survive."""
    from lss_kernels.model.hierarchy import PatchHierarchy
    pool = FieldPool()
    h = PatchHierarchy(pool, H, W, C, SIZES)
    matcher = MatchingCost(pool, H, W)
    lf, rf = pool.vector(3, ti.f32, (H, W)), pool.vector(3, ti.f32, (H, W))
    pool.finalize()
    D = np.full((H, W), 2.5)
    ones = np.ones((H, W))
    aux, (fD, fphi, fplus) = _field([D, ones, ones])
    beta = 0.4 / C
    rng = np.random.default_rng(14)
    messages = Messages(h)
    for trial in range(2):
        left = pair[0] if trial == 0 else rng.random((H, W, 3)).astype(np.float32)
        lf.from_numpy(left)
        rf.from_numpy(pair[1])
        h.build_costs(matcher, lf, rf)
        h.upward(fD, fphi, fplus)
        messages.run(beta, True, True, keep=True)
        for level, s in enumerate(SIZES):
            cost = _inside(h, h.levels[level].cost, level).astype(np.float64)
            want, _ = ref.patch_messages(cost, ref.box_mean(D.astype(np.float32), s), beta,
                                         subpixel=True)
            same = np.isclose(_plane(h.levels[level].d_p), want, rtol=0, atol=1e-4)
            assert same.mean() > 0.99
    aux.destroy()
    pool.destroy()


def test_distinctness_weights_match_the_specification(pair):
    """``ambiguity > 0``: each patch's relay precision is 1 / sigma_p^2 times the
    distinctness of its cost curve (the numpy specification), and 0 where the curve has a
    second minimum as deep as the first."""
    from lss_kernels.model.hierarchy import PatchHierarchy
    from lss_kernels.kernels import lanes
    pool = FieldPool()
    h = PatchHierarchy(pool, H, W, C, SIZES)
    matcher = MatchingCost(pool, H, W)
    lf, rf = pool.vector(3, ti.f32, (H, W)), pool.vector(3, ti.f32, (H, W))
    plain, weighted = Messages(h), Messages(h, pool=pool, ambiguity=0.3)
    pool.finalize()
    lf.from_numpy(pair[0])
    rf.from_numpy(pair[1])
    h.build_costs(matcher, lf, rf)
    relays = []
    for messages in (plain, weighted):
        messages.run(0.0, False, False, keep=True)
        relays.append([h.levels[i].image(h.levels[i].relay_a) for i in range(len(SIZES))])
    for level in range(len(SIZES)):
        cost = _inside(h, h.levels[level].cost, level)
        want = ref.distinctness(cost, 0.3)
        got = lanes.to_image(weighted.distinct[level], H, W)
        np.testing.assert_allclose(got, want, atol=1e-4)
        # the relay is scaled by the distinctness the kernel holds (checked just above to
        # 1e-4 absolute); against ``want`` a relative test fails where the distinctness is
        # near 0 (on CUDA a relay of 1.4718e-7 against 1.4712e-7: float rounding, not a bug)
        np.testing.assert_allclose(relays[1][level], relays[0][level] * got, rtol=1e-5,
                                   atol=1e-12)
        assert 0 < (want < 1).mean() < 1
    pool.destroy()


def test_integer_messages_without_subpixel_refinement(pair):
    """``subpixel=False`` is the release's integer argmin (Eq. 5 over c = 1 .. c_max)."""
    from lss_kernels.model.hierarchy import PatchHierarchy
    pool = FieldPool()
    h = PatchHierarchy(pool, H, W, C, SIZES)
    matcher = MatchingCost(pool, H, W)
    lf, rf = pool.vector(3, ti.f32, (H, W)), pool.vector(3, ti.f32, (H, W))
    pool.finalize()
    lf.from_numpy(pair[0])
    rf.from_numpy(pair[1])
    h.build_costs(matcher, lf, rf)
    Messages(h, subpixel=False).run(0.0, False, False, keep=True)
    for level in range(len(SIZES)):
        cost = _inside(h, h.levels[level].cost, level)
        np.testing.assert_array_equal(_plane(h.levels[level].d_p), cost.argmin(2) + 1)
    pool.destroy()


def test_normal_equation_reduction_matches_lstsq(ti_arch):
    from lss_kernels.model.quadratic import basis
    from lss_kernels.model.shapes import GlobalShapes, WeightPlanes, to_pixel_coefficients
    rng = np.random.default_rng(7)
    h, w = 41, 57   # several tiles, ragged edges
    pool = FieldPool()
    shapes = GlobalShapes(pool, h, w)
    fields = [pool.field(ti.f32, (h, w)) for _ in range(3)]
    pool.finalize()
    wf = rng.random((h, w)) * (rng.random((h, w)) < 0.5)
    wb = rng.random((h, w)) * (wf == 0)
    target = rng.random((h, w)) * 30
    for f, a in zip(fields, (wf, wb, target)):
        f.from_numpy(a.astype(np.float32))
    shapes.fit(WeightPlanes(fields[0], fields[1]), fields[2])
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    for j, wgt in enumerate((wf, wb)):
        U = basis(x, y).reshape(-1, 6)
        sw = np.sqrt(wgt.astype(np.float32).astype(np.float64).reshape(-1))
        sol = np.linalg.lstsq(U * sw[:, None], target.astype(np.float32).reshape(-1) * sw,
                              rcond=None)[0]
        got = to_pixel_coefficients(shapes.theta.to_numpy()[j], h, w)
        np.testing.assert_allclose(U @ got, U @ sol, atol=2e-3)
    assert shapes.updated.to_numpy().tolist() == [1, 1]
    pool.destroy()


def test_shape_keeps_previous_value_with_too_few_rows(ti_arch):
    from lss_kernels.model.shapes import GlobalShapes, WeightPlanes
    pool = FieldPool()
    shapes = GlobalShapes(pool, 8, 8)
    wf, wb, t = (pool.field(ti.f32, (8, 8)) for _ in range(3))
    pool.finalize()
    shapes.set(np.array([0, 0, 0, 0, 0, 5.0]), np.array([0, 0, 0, 0, 0, 2.0]))
    w = np.zeros((8, 8), np.float32)
    w[0, :5] = 1           # five rows: fewer than the six unknowns
    wf.from_numpy(w)
    wb.from_numpy(np.ones((8, 8), np.float32))
    t.from_numpy(np.full((8, 8), 9.0, np.float32))
    shapes.fit(WeightPlanes(wf, wb), t)
    th = shapes.theta.to_numpy()
    assert th[0, 5] == pytest.approx(5.0) and shapes.updated[0] == 0
    assert th[1, 5] == pytest.approx(9.0, abs=1e-3) and shapes.updated[1] == 1
    pool.destroy()


@pytest.mark.parametrize("shape", [(13, 17, 1), (9, 11, 7), (1, 30, 1)])
def test_distance_transform_is_exact(ti_arch, shape):
    from lss_kernels.kernels.distance import INF, DistanceTransform
    rng = np.random.default_rng(8)
    feat = rng.random(shape) < 0.06
    feat.flat[5] = True
    pool = FieldPool()
    f = pool.field(ti.f32, shape)
    pool.finalize()
    f.from_numpy(np.where(feat, 0, INF).astype(np.float32))
    edt = DistanceTransform(shape, max_scratch=5 * max(shape))   # several batches
    edt.run(f, shape[:2])
    pts = np.argwhere(feat)
    grid = np.stack(np.meshgrid(*map(np.arange, shape), indexing="ij"), -1).reshape(-1, 3)
    brute = ((grid[:, None, :] - pts[None]) ** 2).sum(-1).min(1).reshape(shape)
    np.testing.assert_allclose(f.to_numpy(), brute)
    edt.destroy()
    pool.destroy()


def test_field_pool_zero_restores_fresh_fields(ti_arch):
    pool = FieldPool()
    a = pool.field(ti.f32, (3, 4))
    b = pool.vector(2, ti.i32, (5,))
    c = pool.field(ti.i8, (2, 2, 2), offset=(-1, 0, 0))
    pool.finalize()
    a.fill(1.5)
    b.fill(7)
    c.fill(-3)
    pool.zero()
    assert not a.to_numpy().any() and not b.to_numpy().any() and not c.to_numpy().any()
    assert pool.fields == [a, b, c]
    pool.destroy()


@pytest.fixture(scope="module")
def levelset(ti_arch):
    from lss_kernels.model.levelset import LevelSet
    pool = FieldPool()
    ls = LevelSet(pool, H, W, Params())
    pool.finalize()
    ls.setup()
    yield ls
    ls.destroy()
    pool.destroy()


def _median_of(a, k, lanes=None, monkeypatch=None):
    """:class:`MedianFilter` of ``a`` (``k`` by ``k``) through the plain sink."""
    from lss_kernels.kernels import lanes as lanes_module
    from lss_kernels.kernels.median import Assign, MedianFilter
    if lanes is not None:
        monkeypatch.setattr(lanes_module, "lanes_for_arch", lambda: lanes)
    pool = FieldPool()
    median = MedianFilter(pool, *a.shape, k)
    src = pool.field(ti.f32, a.shape)
    dst = pool.field(ti.f32, a.shape)
    pool.finalize()
    assert median.lanes == (lanes or lanes_module.lanes_for_arch())
    src.from_numpy(a.astype(np.float32))
    median.run(src, Assign(dst))
    out = dst.to_numpy()
    pool.destroy()
    return out


def _run_ops(v, ops):
    for op, a, b, keep_min, keep_max in ops:
        if op == "swap":
            v[a], v[b] = v[b], v[a]
            continue
        lo, hi = min(v[a], v[b]), max(v[a], v[b])
        if keep_min:
            v[a] = lo
        if keep_max:
            v[b] = hi
    return v


def _tree_medians(node, held, sorted_column, load, medians):
    """Run a node of :func:`median_network`'s tree in Python: its new columns merged with
    the parent's survivors ``held``; a leaf writes its window's median."""
    columns_at, pre, slots, ops, keep, children, output = node
    columns = [sorted_column(c) for c in columns_at]
    if held is None:
        runs = columns
    elif not pre:
        runs = [held, columns[0]]
    else:
        merged = _run_ops(load(pre[0], columns), pre[1])
        runs = [held, [merged[i] for i in pre[2]]]
    v = _run_ops(load(slots, runs), ops)
    if output >= 0:
        assert len(keep) == 1
        medians[output] = v[keep[0]]
    for child in children:
        _tree_medians(child, [v[i] for i in keep], sorted_column, load, medians)


@pytest.mark.parametrize("k", [3, 5, 7])
def test_median_network_selects_the_medians_of_a_tile_of_windows(k):
    from lss_kernels.kernels.median import _merge_network, median_network
    column_ops, tile, root = median_network(k)
    half = k // 2

    def ops(node):
        own = len(node[3]) + (len(node[1][1]) if node[1] else 0)
        return own + sum(ops(child) for child in node[5])

    # ops (comparators and fixed swaps) per window, after the column sort: the tree against
    # merging all k sorted columns of one window (k = 7: 78.75 against 231) and against
    # Adams' two-window tile (127)
    _, one_window, _ = _merge_network([k] * k, [(k * k - 1) // 2])
    per_window = ops(root) / tile
    assert per_window < 0.55 * len(one_window)
    if k == 7:
        assert tile == 4 and per_window < 80
    load = lambda slots, runs: [-np.inf if s == "lo" else np.inf if s == "hi"
                                else runs[s[0]][s[1]] for s in slots]
    rng = np.random.default_rng(10)
    for trial in range(200):
        # the tile's windows: columns j .. j + k - 1 of the block, j = 0 .. tile - 1
        block = rng.standard_normal((k, tile + k - 1))
        if trial % 4 == 0:
            block = np.round(block)                      # many ties
        columns = []
        for c in range(tile + k - 1):
            col = _run_ops(list(block[:, c]), column_ops)
            assert col[:k] == sorted(block[:, c])
            columns.append(col)
        medians = [None] * tile
        # offsets in the tree count from the first window's centre column
        _tree_medians(root, None, lambda c: columns[c + half], load, medians)
        for j in range(tile):
            assert medians[j] == np.median(block[:, j:j + k])


@pytest.mark.parametrize("k", [3, 5, 7])
def test_median_runs_and_sources_replay_the_networks(k):
    """The kernels run a network's ops by runs of one kind (``_runs``) and load its slots
    from a table (``_sources``): the same values as the ops and slots themselves, for every
    network of the tree and the column sort."""
    from lss_kernels.kernels.median import _runs, _sources, median_network
    column_ops, _, root = median_network(k)
    networks = [(tuple(range(1 + max(max(op[1:3]) for op in column_ops))), column_ops)]

    def collect(node):
        _, pre, slots, ops, _, children, _ = node
        if pre:
            networks.append((pre[0], pre[1]))
        networks.append((slots, ops))
        for child in children:
            collect(child)

    collect(root)
    rng = np.random.default_rng(3)
    for slots, ops in networks:
        n_runs = 1 + max((s[0] for s in slots if isinstance(s, tuple)), default=0)
        runs = [list(rng.standard_normal(k * k)) for _ in range(n_runs)]
        if isinstance(slots[0], int):                    # the column sort: plain values
            expected = list(rng.standard_normal(len(slots)))
            loaded = list(expected)
        else:
            expected = [-np.inf if s == "lo" else np.inf if s == "hi" else runs[s[0]][s[1]]
                        for s in slots]
            sources = runs + [[-np.inf, np.inf]]
            loaded = [sources[run][rank] for run, rank in _sources(slots, n_runs)]
        assert loaded == expected
        replayed = list(loaded)
        for kind, pairs in _runs(ops):
            for a, b in pairs:
                lo, hi = min(replayed[a], replayed[b]), max(replayed[a], replayed[b])
                if kind == "swap":
                    replayed[a], replayed[b] = replayed[b], replayed[a]
                if kind in ("both", "min"):
                    replayed[a] = lo
                if kind in ("both", "max"):
                    replayed[b] = hi
        assert replayed == _run_ops(list(expected), ops)


@pytest.mark.parametrize("k", [1, 7])
def test_settle_counts_sign_flips_and_writes_eq3(ti_arch, k):
    """``LevelSet.settle``: phi = median(phi_next); ``flipped`` counts the pixels whose sign
    differs from phi's previous content, ``area`` the pixels > 0, and D is Eq. 3 of the new
    phi (Theta_1 where phi > 0, else Theta_2), clamped to [0, c_max]."""
    from lss_kernels.model.levelset import LevelSet
    from lss_kernels.model.shapes import GlobalShapes
    pool = FieldPool()
    ls = LevelSet(pool, 9, 14, Params(median_size=k))
    shapes = GlobalShapes(pool, 9, 14)
    pool.finalize()
    rng = np.random.default_rng(30 + k)
    before = rng.standard_normal((9, 14)).astype(np.float32)
    src = rng.standard_normal((9, 14)).astype(np.float32)
    theta = np.array([[0.0, 0.0, 0.0, 3.0, 0.0, 5.0], [0.0, 0.0, 0.0, 0.0, 3.0, 0.0]])
    shapes.set(theta[0], theta[1])
    ls.d_limit[None] = 6.5
    ls.phi.from_numpy(ls.extent.padded(before))
    ls.phi_next.from_numpy(ls.extent.padded(src))
    ls.settle(shapes)
    after = ref.median_filter(src, k) if k > 1 else src
    np.testing.assert_array_equal(ls.extent.image(ls.phi), after)
    assert ls.flipped[None] == ((after > 0) != (before > 0)).sum() > 0
    assert ls.area[None] == (after > 0).sum() > 0
    y, x = np.mgrid[0:9, 0:14].astype(np.float64)
    xn, yn = (x - shapes.cx) * shapes.inv_s, (y - shapes.cy) * shapes.inv_s
    th1, th2 = 3.0 * xn + 5.0, 3.0 * yn
    want = np.clip(np.where(after > 0, th1, th2), 0.0, 6.5)
    assert (want == 6.5).any() and (want == 0.0).any()     # both clamps are exercised
    np.testing.assert_allclose(ls.extent.image(ls.D), want, atol=1e-5)
    pool.destroy()


def test_net_change_counts_changed_labels_and_the_boundary(ti_arch):
    """``LevelSet.net_change`` (the stopping rule's measure): ``changed`` counts the pixels
    whose label (phi > 0) differs from the last call's, ``boundary`` the foreground pixels
    with a 4-neighbour of the background inside the image (the image's own edge is not a
    boundary)."""
    from lss_kernels.model.levelset import LevelSet
    pool = FieldPool()
    ls = LevelSet(pool, 9, 14, Params())
    pool.finalize()
    rng = np.random.default_rng(7)
    y, x = np.mgrid[0:9, 0:14]
    first = (4.0 - np.hypot(x - 2.0, y - 4.0)).astype(np.float32)   # a disc cut by the edge
    second = first + 0.3 * rng.standard_normal((9, 14)).astype(np.float32)

    def boundary(fg):
        p = np.pad(fg, 1, mode="edge")
        inner = p[:-2, 1:-1] & p[2:, 1:-1] & p[1:-1, :-2] & p[1:-1, 2:]
        return int((fg & ~inner).sum())

    ls.phi.from_numpy(ls.extent.padded(first))
    ls.net_change()
    assert ls.boundary[None] == boundary(first > 0) == 15    # rows 1 and 7, and x = 5
    ls.phi.from_numpy(ls.extent.padded(second))
    ls.net_change()
    changed = ((second > 0) != (first > 0)).sum()
    assert ls.changed[None] == changed > 0
    assert ls.boundary[None] == boundary(second > 0)
    ls.net_change()                                   # the reference was renewed
    assert ls.changed[None] == 0
    pool.destroy()


def test_moved_measures_each_pixel_on_its_own_layers_shape(ti_arch):
    """``GlobalShapes.moved``: the largest |Theta_j - reference_j| over the image, with j the
    pixel's own layer (0 where phi > 0), against numpy; then the reference is Theta."""
    from lss_kernels.model.levelset import LevelSet
    from lss_kernels.model.quadratic import basis
    from lss_kernels.model.shapes import GlobalShapes
    pool = FieldPool()
    ls = LevelSet(pool, 9, 14, Params())
    shapes = GlobalShapes(pool, 9, 14)
    pool.finalize()
    y, x = np.mgrid[0:9, 0:14]
    phi = np.where(x < 5, 1.0, -1.0).astype(np.float32)       # the foreground: x < 5
    ls.phi.from_numpy(ls.extent.padded(phi))
    before = np.array([[0.0, 0.0, 0.0, 1.0, 0.0, 5.0], [0.0, 0.0, 0.0, 0.0, 0.0, 2.0]])
    # Theta_1 moves by 3 x_n + 1: 1.79 at x = 0 in the foreground, 3.79 at x = 13 outside it
    # (which must not count); Theta_2 by 0.25 everywhere
    after = before + np.array([[0.0, 0.0, 0.0, 3.0, 0.0, 1.0], [0.0, 0.0, 0.0, 0.0, 0.0, 0.25]])
    shapes.set(before[0], before[1])
    shapes.moved(ls.phi)
    shapes.set(after[0], after[1])
    shapes.moved(ls.phi)
    z = basis((x - shapes.cx) * shapes.inv_s, (y - shapes.cy) * shapes.inv_s)
    change = np.abs(z @ (after - before).T)                    # (9, 14, 2)
    want = max(change[..., 0][x < 5].max(), change[..., 1][x >= 5].max())
    assert want == pytest.approx(3.0 * 6.5 / 7.0 - 1.0)      # Theta_1 at x = 0
    assert shapes.change[None] == pytest.approx(want, rel=1e-5)
    shapes.moved(ls.phi)                                       # the reference was renewed
    assert shapes.change[None] == 0.0
    pool.destroy()


def _census_words(image):
    """:func:`lss_kernels.reference.kernels.census` packed as the kernel's two words."""
    bits = ref.census(image).astype(np.uint32)
    words = np.zeros(bits.shape[:2] + (2,), np.uint32)
    for bit in range(bits.shape[-1]):
        words[..., bit // 32] |= bits[..., bit] << np.uint32(bit % 32)
    return words


@pytest.mark.parametrize("height, width", [(37, 53), (5, 9)])
def test_census_transform_matches_the_specification_bit_for_bit(ti_arch, height, width):
    """Colours in quarters: many neighbours of the centre's own colour (never below it),
    and no near-ties between the float32 greys and the reference's float64 ones."""
    rng = np.random.default_rng(height + width)
    image = (np.round(rng.random((height, width, 3)) * 4) / 4).astype(np.float32)
    pool = FieldPool()
    matcher = MatchingCost(pool, height, width, "ad_census")
    img = pool.vector(3, ti.f32, (height, width))
    pool.finalize()
    img.from_numpy(image)
    matcher.setup(img, img)
    words = matcher.census_words(0)
    np.testing.assert_array_equal(words, _census_words(image.astype(np.float64)))
    np.testing.assert_array_equal(matcher.census_words(1), words)
    pool.destroy()


def test_derivatives_and_curvature_match_reference(levelset):
    rng = np.random.default_rng(11)
    phi = _smooth_phi(rng).astype(np.float32)
    levelset.phi.from_numpy(levelset.extent.padded(phi))
    band, levelset.band = levelset.band, 0.0                  # kappa and N everywhere
    try:
        levelset.derivatives()
    finally:
        levelset.band = band
    _compare_derivatives(levelset, phi)


def _compare_derivatives(ls, phi):
    """phi_x, kappa and N of a LevelSet after ``derivatives()`` against the float64
    reference (N_y holds phi_y, kappa the second derivatives; both where |grad phi| is not
    tiny)."""
    phi = phi.astype(np.float32).astype(np.float64)
    px, py = ref.gaussian_derivatives(phi, 4.0)[:2]
    np.testing.assert_allclose(ls.image(ls.phi_x), px, atol=1e-5)
    k, nx, ny = ref.curvature(ref.gaussian_derivatives(phi, 4.0), 10.0)
    norm = np.hypot(px, py)
    sel = norm > 0.05 * norm.max()
    assert sel.mean() > 0.5
    np.testing.assert_allclose(ls.image(ls.kappa)[sel], k[sel], atol=2e-3)
    np.testing.assert_allclose(ls.image(ls.normal_x)[sel], nx[sel], atol=1e-4)
    np.testing.assert_allclose(ls.image(ls.normal_y)[sel], ny[sel], atol=1e-4)


def _check_derivatives_at_size(phi):
    """A fresh LevelSet of ``phi``'s size against the reference derivatives."""
    from lss_kernels.model.levelset import LevelSet
    pool = FieldPool()
    ls = LevelSet(pool, *phi.shape, Params(narrow_band=0))    # kappa and N everywhere
    pool.finalize()
    ls.setup()
    ls.phi.from_numpy(ls.extent.padded(phi.astype(np.float32)))
    ls.derivatives()
    _compare_derivatives(ls, phi)
    ls.destroy()
    pool.destroy()


def test_derivatives_inside_and_near_the_borders_of_a_larger_image(ti_arch):
    """At 40 x 48 both filter passes take the interior fast path (farther than the
    half-width 14 from the border) as well as the reflected border path."""
    rng = np.random.default_rng(13)
    y, x = np.mgrid[0:40, 0:48]
    _check_derivatives_at_size((15.0 - np.hypot(x - 20.0, (y - 18.0) * 1.2)) / 10.0
                               + 0.05 * rng.standard_normal((40, 48)))


def test_derivatives_of_an_image_smaller_than_the_filter(ti_arch):
    """10 x 12 pixels under a half-width of 14: the symmetric border reflects repeatedly."""
    _check_derivatives_at_size(np.random.default_rng(15).standard_normal((10, 12)))


def test_derivatives_of_an_image_between_one_and_two_filter_half_widths(ti_arch):
    """20 x 17 pixels under a half-width of 14: rows 6 .. 13 reflect into both margins of
    the row-filtered scratch, most columns reflect at both sides."""
    _check_derivatives_at_size(np.random.default_rng(17).standard_normal((20, 17)))


@ti.data_oriented
class _GivenB:
    """Boundary costs whose B(x, y, c) is a given map, whatever c."""

    def __init__(self, b):
        self.b = b

    @ti.func
    def b_at(self, y, x, c):
        return self.b[y, x]


def _check_step(phi, bands, lanes=None, monkeypatch=None):
    """The Eq. 2 step (``_step``, after ``derivatives`` and ``boundary_weight``: B at
    Theta_1 and the row pass of grad B) of a LevelSet of ``phi``'s size against the float64
    reference, for each narrow band in ``bands`` (phi units; 0: none); also phi's derivatives
    when there is no band.  B is a given map here (a stand-in for the boundary costs'
    ``b_at``).  Returns the fraction of pixels outside the last band."""
    from lss_kernels.kernels import lanes as lanes_module
    from lss_kernels.model.levelset import LevelSet
    from lss_kernels.model.occlusion import OcclusionGeometry
    from lss_kernels.model.shapes import GlobalShapes
    if lanes is not None:
        monkeypatch.setattr(lanes_module, "lanes_for_arch", lambda: lanes)
    h, w = phi.shape
    rng = np.random.default_rng(21)
    p = Params()
    pool = FieldPool()
    ls = LevelSet(pool, h, w, p)
    assert ls.lanes == (lanes or lanes_module.lanes_for_arch())
    shapes = GlobalShapes(pool, h, w)
    occ = OcclusionGeometry(pool, h, w, C)
    cost = pool.field(ti.f32, (h, w, C))
    given_b = _GivenB(pool.field(ti.f32, (h, w)))
    pool.finalize()
    ls.setup()
    # Theta_1 and Theta_2 in the normalised quadratic basis; their maps at the pixels
    theta = np.array([[0.4, -0.2, 0.3, 1.1, -0.6, 4.5], [0.0, 0.0, -0.2, 0.5, 0.3, 2.2]])
    shapes.set(theta[0], theta[1])
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    xn, yn = (x - shapes.cx) * shapes.inv_s, (y - shapes.cy) * shapes.inv_s
    basis = np.stack([xn * xn, xn * yn, yn * yn, xn, yn, np.ones_like(xn)])
    th1, th2 = (np.tensordot(t.astype(np.float32), basis, 1) for t in theta)
    phi = phi.astype(np.float32)
    b_map = (0.5 + rng.random((h, w))).astype(np.float32)
    dtheta = rng.uniform(-3.0, 3.0, (h, w)).astype(np.float32)
    volume = rng.random((h, w, C)).astype(np.float32)
    ls.phi.from_numpy(ls.extent.padded(phi))
    given_b.b.from_numpy(b_map)
    occ.delta_theta.from_numpy(occ.extent.padded(dtheta))
    cost.from_numpy(volume)
    kappa, n_x, n_y = ref.curvature(ref.gaussian_derivatives(phi.astype(np.float64),
                                                             CURVATURE_SIGMA),
                                    CURVATURE_CLIP)
    b_x, b_y = ref.gaussian_derivatives(b_map.astype(np.float64), CURVATURE_SIGMA)[:2]
    for band in bands:
        ls.band = band
        ls.derivatives()
        if band == 0:
            _compare_derivatives(ls, phi)
        ls.boundary_weight(given_b, shapes)
        ls._step(cost, C, shapes, occ, p.dt, p.mu, band)
        want = ref.levelset_step(phi, volume, th1, th2, dtheta, b_map, b_x, b_y, kappa, n_x,
                                 n_y, p.dt, p.mu, BOUNDARY_CLIP, band)
        got = ls.extent.image(ls.phi_next)
        assert np.abs(got - phi).max() > 0.05      # the step moves phi
        np.testing.assert_allclose(got, want, atol=1e-5)
        # outside the band phi is kept exactly, inside it moves
        outside = np.abs(phi) > band if band > 0 else np.zeros(phi.shape, bool)
        np.testing.assert_array_equal(got[outside], phi[outside])
        assert np.abs(got - phi)[~outside].min() > 0
        # phi_x, whose sign the ray cast reads everywhere, is computed outside the band too
        np.testing.assert_allclose(ls.image(ls.phi_x),
                                   ref.gaussian_derivatives(phi.astype(np.float64), 4.0)[0],
                                   atol=1e-5)
    ls.destroy()
    pool.destroy()
    return outside.mean()


@pytest.mark.parametrize("lanes", [None, 1])
def test_eq2_step_matches_reference(ti_arch, monkeypatch, lanes):
    """On an image whose width (34) ends in a partial block of lanes, with and without a
    band; also with blocks of one pixel, the GPUs' layout."""
    phi = _smooth_phi(np.random.default_rng(21)) * 2.0     # about -2 .. 2.4
    assert 0.2 < _check_step(phi, (0.0, 1.0), lanes, monkeypatch) < 0.8


@pytest.mark.parametrize("lanes", [None, 1])
def test_eq2_step_in_a_narrow_band_skips_only_what_it_never_reads(ti_arch, monkeypatch, lanes):
    """A band of 10.5 px around two discs in a 70 x 101 image, most blocks far from it:
    the step computes kappa, N, B and the row pass of grad B only within the filters' reach
    of the band's blocks, and still equals the reference that computes them everywhere."""
    y, x = np.mgrid[0:70, 0:101]
    distance = np.maximum(12.0 - np.hypot(x - 30.0, y - 25.0),
                          9.0 - np.hypot(x - 75.0, (y - 50.0) * 1.4))
    phi = 0.01 * distance + 0.002 * np.random.default_rng(5).standard_normal(x.shape)
    assert _check_step(phi, (0.105,), lanes, monkeypatch) > 0.6


def test_curvature_of_a_disc_is_minus_one_over_radius(levelset):
    y, x = np.mgrid[0:H, 0:W]
    r = 9.0
    phi = (r - np.hypot(x - 17, y - 11)) * 0.01      # foreground inside: kappa = -1/r
    levelset.phi.from_numpy(levelset.extent.padded(phi.astype(np.float32)))
    levelset.derivatives()
    kappa = levelset.image(levelset.kappa)
    # on the row through the centre, away from the top and bottom borders (symmetric borders
    # mirror the disc there)
    assert kappa[11, 17 - 9] == pytest.approx(-1 / r, rel=0.06)
    assert kappa[11, 17 + 9] == pytest.approx(-1 / r, rel=0.06)


def test_reinitialise_gives_scaled_signed_distance(levelset):
    y, x = np.mgrid[0:H, 0:W]
    mask = (x >= 10) & (x < 25)                 # a vertical band: distance along x only
    levelset.start(mask, C)
    phi = levelset.extent.image(levelset.phi)
    dist_in = np.minimum(x - 10, 24 - x) + 0.5
    dist_out = np.where(x < 10, 10 - x, x - 24) - 0.5
    np.testing.assert_allclose(phi, 0.01 * np.where(mask, dist_in, -dist_out), atol=1e-6)


# The median tests come last: they start Taichi again (conftest's ``fresh_taichi``; the
# module's ``hierarchy`` and ``levelset`` fixtures are not used after this point), so that
# each pool numbers its SNodes alike and the 7x7 network compiles once per lane width.


def test_median_filter_matches_numpy(fresh_taichi):
    rng = np.random.default_rng(9)
    a = rng.standard_normal((H, W)).astype(np.float32)
    np.testing.assert_array_equal(_median_of(a, 7), ref.median_filter(a, 7))


@pytest.mark.parametrize("lanes", [8, 1])
@pytest.mark.parametrize("k, height, width", [(3, 5, 9), (5, 13, 11), (5, 5, 12), (7, 13, 1),
                                              (7, 5, 2), (7, 13, 13)])
def test_median_filter_matches_numpy_for_odd_and_tiny_sizes(fresh_taichi, monkeypatch, lanes,
                                                            k, height, width):
    """Rows in blocks of 8 (the CPU's; 13 rows end in a partial block) and of 1 (the GPUs')."""
    rng = np.random.default_rng(k * 100 + width)
    a = np.round(rng.standard_normal((height, width)) * 2).astype(np.float32)
    np.testing.assert_array_equal(_median_of(a, k, lanes, monkeypatch), ref.median_filter(a, k))


def test_median_filter_matches_numpy_with_ties_and_borders(fresh_taichi):
    rng = np.random.default_rng(12)
    a = np.round(rng.standard_normal((H, W)) * 2).astype(np.float32)
    np.testing.assert_array_equal(_median_of(a, 7), ref.median_filter(a, 7))


def test_background_sweep_matches_reference(ti_arch):
    """The background's plane sweep (per-pixel standardised cost curves summed over the
    visible background, pixels near Theta_1 left out) against the float64 reference: the
    per-candidate sums and their count, the sum at the fitted Theta_2, and the plane it
    chooses; a faint dip at c = 3 under noise wins over a Theta_2 fitted at 5.5, a margin
    larger than the dip keeps Theta_2.  Swept pixels with flat curves have no vote."""
    from lss_kernels.model.shapes import GlobalShapes
    from lss_kernels.model.sweep import FLAT, NEAR, BackgroundSweep, choose_plane
    from lss_kernels.reference.sweep import background_sweep, sweep_totals
    rng = np.random.default_rng(41)
    pool = FieldPool()
    shapes = GlobalShapes(pool, H, W)
    sweep = BackgroundSweep(pool, H, W, C)
    ext = sweep.extent
    cost = pool.field(ti.f32, ext.bucket + (C,), volume=True)
    phi, phi_plus, cons = (pool.field(ti.f32, ext.bucket, bucket=True) for _ in range(3))
    pool.finalize()
    theta = np.array([[0.3, 0.0, -0.2, 0.4, 0.1, 5.0], [0.0, 0.2, 0.0, -0.3, 0.0, 5.5]])
    shapes.set(theta[0], theta[1])
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    th1, th2 = (ref.shape_value(t.astype(np.float32), x, y, (H, W)) for t in theta)
    f32 = lambda a: a.astype(np.float32).astype(np.float64)
    phi_np, phi_plus_np = f32(rng.uniform(-1, 1, (H, W))), f32(rng.uniform(-1, 1, (H, W)))
    cons_np = f32(th1 + rng.uniform(-4, 4, (H, W)))
    visible = (phi_np < 0) & (phi_plus_np < 0)
    sel = visible & (np.abs(cons_np - th1) >= NEAR)
    assert 0.1 < sel.mean() < 0.3
    volume = rng.random((H, W, C)) * 0.05 + 0.3
    volume[:, :, 2] -= 0.01                     # the background's faint dip at c = 3
    flat = tuple(np.argwhere(sel)[:5].T)
    volume[flat] = 0.2                          # flat curves on swept pixels: no vote
    volume = f32(volume)
    for f, a in ((cost, volume), (phi, phi_np), (phi_plus, phi_plus_np), (cons, cons_np)):
        f.from_numpy(ext.padded(a.astype(np.float32)))
    sweep.standardise(cost)
    assert not sweep.extent.image(sweep.inv_spread)[flat].any()
    sd = volume.std(axis=2)
    z = (volume - volume.mean(axis=2, keepdims=True)) / np.where(sd > FLAT, sd, 1)[..., None]
    z[sd <= FLAT] = 0.0
    sweep._sweep(cost, shapes, phi, phi_plus, cons, NEAR)
    totals = sweep.totals.to_numpy()
    assert totals[C + 1] == sel.sum()
    np.testing.assert_allclose(totals[:C], z[sel].sum(axis=0), atol=1e-3)
    k = np.clip(th2 - 1.0, 0.0, C - 1.0)
    k0 = np.minimum(np.floor(k).astype(int), C - 2)
    at_theta2 = (1 - (k - k0)) * np.take_along_axis(z, k0[..., None], 2)[..., 0] + \
        (k - k0) * np.take_along_axis(z, k0[..., None] + 1, 2)[..., 0]
    assert totals[C] == pytest.approx(at_theta2[sel].sum(), abs=1e-3)
    np.testing.assert_allclose(totals, sweep_totals(volume, visible, th1, th2, cons_np),
                               atol=1e-3)
    want = background_sweep(volume, visible, th1, th2, cons_np, 0.05)
    assert want is not None and abs(want - 3.0) < 0.5
    assert choose_plane(totals.astype(np.float64), 0.05, H * W) == pytest.approx(want, abs=1e-3)
    assert background_sweep(volume, visible, th1, th2, cons_np, 5.0) is None
    due = lambda it, margin: sweep.run(it, Params(background_sweep=margin), cost, shapes, phi,
                                       phi_plus, cons)
    assert due(1, 5.0) is None and due(11, 0.05) is None and due(3, 0.0) is None
    np.testing.assert_allclose(shapes.theta.to_numpy(), theta, atol=1e-6)
    got = due(20, 0.05)
    assert got == pytest.approx(want, abs=1e-3)
    np.testing.assert_allclose(shapes.theta.to_numpy()[1], [0, 0, 0, 0, 0, got], atol=1e-6)
    np.testing.assert_allclose(shapes.theta.to_numpy()[0], theta[0], atol=1e-6)
    pool.destroy()


def test_background_sweep_needs_a_share_of_the_image():
    """A deep, distinct dip swept over fewer than ``MIN_SHARE`` of the image's pixels sets no
    plane: a few pixels' curves are no background."""
    from lss_kernels.model.sweep import MIN_SHARE, choose_plane
    mean = np.array([0.2, 0.2, -1.5, 0.2, 0.2, 0.3, 0.3, 0.1])
    for n, chosen in ((MIN_SHARE * 1e4 - 1, False), (MIN_SHARE * 1e4, True)):
        totals = np.concatenate([mean * n, [0.0 * n, n]])
        assert (choose_plane(totals, 0.05, 100 * 100) is not None) == chosen


def test_plane_vertex_of_a_parabola_and_at_the_ends():
    from lss_kernels.model.sweep import plane_vertex
    c = np.arange(1, 8, dtype=np.float64)
    mean = (c - 3.3) ** 2
    assert plane_vertex(mean, int(np.argmin(mean))) == pytest.approx(3.3)
    assert plane_vertex(mean[::-1].copy(), 6) == 7.0           # the last candidate
    assert plane_vertex(np.array([1.0, 0.0, 5.0]), 0) == 1.0    # the first candidate
    assert plane_vertex(np.array([1.0, 1.0, 1.0]), 1) == 2.0    # flat: no vertex


def test_a_broad_bowl_is_no_distinct_dip():
    """A slanted background sweeps to a broad bowl (paper15 scene 2: 25 of 60 candidates
    below half its depth), a background near one plane to a narrow dip."""
    from lss_kernels.model.sweep import distinct_dip
    c = np.arange(1, 61, dtype=np.float64)
    bowl = 1.0 - np.exp(-((c - 40) / 25.0) ** 2)
    dip = np.where(np.abs(c - 12) <= 1, -1.0, 0.0)
    assert not distinct_dip(bowl, int(np.argmin(bowl)))
    assert distinct_dip(dip, 11)
    assert distinct_dip(np.array([0.0, -1.0, 0.0, 0.1]), 1)     # small ranges: 2 candidates
