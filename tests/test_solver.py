"""The whole solver on rendered two-layer scenes with exact ground truth."""
import numpy as np
import pytest
import taichi as ti

from lss_kernels import Params, Solver, solve
from lss_kernels.metrics import score
from lss_kernels.model.shapes import WEIGHT_POWER
from lss_kernels.params import OCC_SIGMA, OCC_THRESHOLD
from lss_kernels.scenes import make_scene


@pytest.fixture(scope="module")
def easy(ti_arch):
    scene = make_scene("easy")
    result = solve(scene.left, scene.right, scene.d_max, scene.init_ellipse)
    return scene, result


def test_recovers_the_boundary_of_an_easy_scene(easy):
    scene, result = easy
    s = score(result.disparity, result.occlusion, scene)
    assert s["occ_f1"] >= 0.9
    assert s["bad4"] <= 5.0
    iou = (result.foreground & scene.fg_left).sum() / (result.foreground | scene.fg_left).sum()
    assert iou >= 0.95
    # Theta in left-view disparity: the planes at 24 and 8 pixels
    assert result.theta_fg[5] + result.theta_fg[3] * 60 == pytest.approx(24.0, abs=0.5)
    assert result.theta_bg[5] == pytest.approx(8.0, abs=0.5)


def test_background_sweep_planes_lie_on_the_background(easy):
    """The easy scene's textured background at 8 px is fronto-parallel: the first iteration's
    plane explains it better than the first fit and is set; every plane the sweep set lies
    at the background's disparity, and ``summary.json`` counts them."""
    from lss_kernels.apps.jobs import sweep_summary
    scene, result = easy
    planes = [(s["iteration"], s["background_plane"]) for s in result.history
              if s["background_plane"] is not None]
    assert planes and planes[0][0] == 1 and all(abs(d - 8.0) < 0.5 for _, d in planes)
    assert all(it <= 10 or it % 10 == 0 for it, _ in planes)
    summary = sweep_summary(result.history)
    assert summary["planes_set"] == len(planes)
    assert summary["last"] == (None if not planes else
                               {"iteration": planes[-1][0], "disparity": round(planes[-1][1], 3)})
    assert sweep_summary([{"iteration": 1, "background_plane": None}]) == {"planes_set": 0,
                                                                           "last": None}


def test_default_floor_stops_a_settled_boundary_early_at_the_same_answer(easy):
    """The easy scene's boundary settles within a few windows: the default floor lets the
    rule stop it long before 200 iterations, and holding it to 200 changes nothing that is
    scored."""
    scene, result = easy
    held = solve(scene.left, scene.right, scene.d_max, scene.init_ellipse,
                 params=Params(min_iterations=200))
    assert Params().min_iterations <= result.iterations < 200 <= held.iterations
    early, late = (score(r.disparity, r.occlusion, scene) for r in (result, held))
    assert early["occ_f1"] == pytest.approx(late["occ_f1"], abs=0.01)
    assert early["bad4"] == pytest.approx(late["bad4"], abs=0.5)
    both, either = result.foreground & held.foreground, result.foreground | held.foreground
    assert both.sum() / either.sum() >= 0.99


def test_result_maps_are_finite_and_consistent(easy):
    scene, result = easy
    H, W = scene.left.shape[:2]
    for name in ("disparity", "phi", "consensus_mean", "consensus_sigma"):
        a = getattr(result, name)
        assert a.shape == (H, W) and np.isfinite(a).all(), name
    assert result.occlusion.dtype == bool and result.foreground.dtype == bool
    assert not (result.occlusion & result.foreground).any()
    assert (result.disparity >= 0).all()
    assert result.iterations == len(result.history) >= 1
    assert result.stop_reason.startswith("converged")
    assert result.timings["total"] > 0


@pytest.mark.slow
def test_stepping_gives_the_same_result_as_solve(easy):
    scene, result = easy
    solver = Solver(scene.left, scene.right, scene.d_max, scene.init_ellipse)
    while not solver.done:
        solver.step()
    stepped = solver.result()
    solver.close()
    assert stepped.iterations == result.iterations
    np.testing.assert_array_equal(stepped.disparity, result.disparity)
    np.testing.assert_array_equal(stepped.phi, result.phi)


@pytest.mark.slow
def test_reset_solves_another_pair_exactly_like_a_new_solver(ti_arch):
    a, b = make_scene("tiny", seed=0), make_scene("tiny", seed=1)
    params = Params(max_iterations=25)
    fresh = {"a": solve(a.left, a.right, a.d_max, a.init_ellipse, params=params)}
    solver = Solver(b.left, b.right, b.d_max, b.init_ellipse, params=params)
    fresh["b"] = solver.run()
    for name, scene in (("a", a), ("b", b)):
        solver.reset(scene.left, scene.right, scene.d_max, scene.init_ellipse)
        assert solver.iteration == 0 and not solver.done and solver.history == []
        again = solver.run()
        assert again.iterations == fresh[name].iterations
        for key in ("phi", "disparity", "occlusion", "consensus_mean", "theta_fg"):
            np.testing.assert_array_equal(getattr(again, key), getattr(fresh[name], key))
    with pytest.raises(ValueError, match=r"reset: expected a 64x48 pair with ceil\(d_max / 2\) "
                       r"= \d+ .* got 64x47"):
        solver.reset(a.left[:47], a.right[:47], a.d_max, a.init_ellipse)
    with pytest.raises(ValueError, match=r"ceil\(d_max / 2\)"):
        solver.reset(a.left, a.right, 4 * a.d_max, a.init_ellipse)
    solver.close()
    with pytest.raises(RuntimeError, match="closed"):
        solver.reset(a.left, a.right, a.d_max, a.init_ellipse)


@pytest.mark.slow
def test_recovers_a_slanted_curved_scene(ti_arch):
    scene = make_scene("slanted")
    result = solve(scene.left, scene.right, scene.d_max, scene.init_ellipse_cyclopean,
                   init_frame="cyclopean")
    s = score(result.disparity, result.occlusion, scene)
    assert s["occ_f1"] >= 0.85
    assert s["bad4"] <= 10.0


@pytest.mark.slow
def test_callback_sees_every_iteration_and_can_stop(ti_arch):
    scene = make_scene("easy")
    seen = []

    def callback(solver, stats):
        seen.append(stats["iteration"])
        return stats["iteration"] < 7

    result = solve(scene.left, scene.right, scene.d_max, scene.init_ellipse,
                   params=Params(max_iterations=50), callback=callback)
    assert seen == list(range(1, 8))
    assert result.iterations == 7 and "callback" in result.stop_reason


@pytest.mark.slow
def test_memory_stays_within_the_volume_budget(ti_arch):
    scene = make_scene("easy")
    solver = Solver(scene.left, scene.right, scene.d_max, scene.init_ellipse,
                    params=Params(max_iterations=1))
    H, W = scene.left.shape[:2]
    levels = len(solver.params.patch_sizes)
    budget = 4 * H * W * solver.c_max * (levels + 2)
    # the intermediate levels carry margins of patch centres outside the image
    m = [lev.margin for lev in solver.hierarchy.levels]
    margins = sum(4 * ((H + 2 * k) * (W + 2 * k) - H * W) * solver.c_max for k in m)
    # 2-D fields: 64 for the model's maps, 5 per level for the message cache (key, the two
    # candidates' costs and refined positions), 4 for the plane sweep and its per-row sums
    planes = (68 + 5 * levels) * H * W * 4 + (H + 1) * (solver.c_max + 2) * 4
    # the three row-filtered scratch planes of the separable filters carry half-width
    # margin rows above and below; they, phi's four derivative planes and the message
    # caches are lane planes, whose rows are padded to whole blocks of lanes
    half, padded = solver.levelset.filters.half, solver.levelset.blocks * solver.levelset.lanes
    filter_margins = 3 * 2 * half * padded * 4 + (7 + 5 * levels) * H * (padded - W) * 4
    # the median's sorted columns (k per pixel) and its output plane, one set shared by the
    # solver's 7x7 filters, have the shape of the merge tree's scratch, in blocks of lanes
    # rows over whole tiles of columns; the sorted columns also hold k // 2 reflected
    # columns on either side
    from lss_kernels.kernels.median import scratch_shape
    k, ls = solver.params.median_size, solver.levelset.median
    assert solver.initialiser.median._tree is ls._tree
    tile, (scratch_h, scratch_w) = ls._tree.network[1], scratch_shape(ls.bucket)
    rows = -(-scratch_h // ls.lanes) * ls.lanes
    columns = tile * -(-scratch_w // tile)
    filter_margins += (k * rows * (columns + 2 * (k // 2)) + rows * columns) * 4
    # set-up scratch kept for the solver's life: B_occ's block of rows (as many values as
    # CHUNK planes, rounded up to whole rows) and a 2-D distance map, and the distance
    # transforms' line buffers (3 arrays of lines x longest axis): phi's (all lines of the
    # longest axis), B_occ's and B_mono's (~4 planes of elements)
    from lss_kernels.model.costs import CHUNK
    chunk = (min(CHUNK, solver.c_max) + 1) * H * W * 4
    longest = max(H, W, solver.c_max)
    lines = 3 * 4 * (max(H, W) * (max(H, W) + 1) + 2 * (4 * H * W + 2 * longest))
    # the refinement (model/refine.py): its cost store (2 range + 1 planes), 6 planes, five
    # 4-channel box planes, the census words of both views (2 + 2) and the candidates' span
    refine = (solver.refinement.K + 6 + 5 * 4 + 4) * H * W * 4 + 8
    assert solver.memory_bytes <= (budget + margins + planes + filter_margins + chunk + lines
                                   + refine)
    solver.close()


@pytest.mark.slow
def test_shape_weights_drop_consensus_that_points_outside_the_other_image(ti_arch):
    """Eq. 8 weights: precision^2 on the foreground / visible background, but zero where the
    consensus correspondence x +- c leaves the image (costs there compare clamped borders)."""
    scene = make_scene("easy")
    solver = Solver(scene.left, scene.right, scene.d_max, scene.init_ellipse)
    solver.step()
    H, W = solver.H, solver.W
    rng = np.random.default_rng(0)
    mean = rng.uniform(0, solver.c_max, (H, W)).astype(np.float32)
    prec = rng.uniform(0.5, 2.0, (H, W)).astype(np.float32)
    solver.hierarchy.consensus_mean.from_numpy(solver.extent.padded(mean))
    solver.hierarchy.precision.from_numpy(solver.extent.padded(prec))
    assert WEIGHT_POWER == 2
    weight_fg, weight_bg = ti.field(ti.f32, (H, W)), ti.field(ti.f32, (H, W))

    @ti.kernel
    def evaluate(weights: ti.template()):
        for y, x in weight_fg:
            w = weights.row_weights(y, x)
            weight_fg[y, x] = w[0]
            weight_bg[y, x] = w[1]

    evaluate(solver.shapes.weights)
    x = np.arange(W)[None, :]
    inside = (x - mean >= 0) & (x + mean <= W - 1)
    assert 0.05 < (~inside).mean() < 0.95
    phi = solver.extent.image(solver.levelset.phi)
    visible = (phi < 0) & (solver.extent.image(solver.occ.phi_plus) < 0)
    np.testing.assert_allclose(weight_fg.to_numpy(),
                               np.where(inside & (phi >= 0), prec ** 2, 0.0), rtol=1e-6)
    np.testing.assert_allclose(weight_bg.to_numpy(),
                               np.where(inside & visible, prec ** 2, 0.0), rtol=1e-6)
    solver.close()


@pytest.mark.slow
@pytest.mark.parametrize("patience", [1, 3])
def test_stopping_rule_waits_for_patience_quiet_windows(ti_arch, patience):
    scene = make_scene("easy")
    params = Params(stop_shift=1e9, stop_surface=1e9, stop_window=5, stop_patience=patience,
                    min_iterations=0)
    result = solve(scene.left, scene.right, scene.d_max, scene.init_ellipse, params=params)
    assert result.iterations == 5 * patience
    assert result.stop_reason.startswith(f"converged at iteration {5 * patience}")
    assert result.stop_reason.endswith("in its last window)" if patience == 1 else
                                       f"in {patience} windows in a row)")


def _correlate(a, taps, axis):
    """sum_i taps[h + i] a[.. + i ..] along ``axis``, edges repeated (the kernels' clamping)."""
    h = len(taps) // 2
    pad = [(0, 0)] * a.ndim
    pad[axis] = (h, h)
    p = np.pad(a, pad, mode="edge")
    n = a.shape[axis]
    return sum(t * np.take(p, range(i, i + n), axis=axis) for i, t in enumerate(taps))


def test_boundary_costs_match_a_numpy_reference(ti_arch):
    """B_occ (Eq. 1): distance to the voxels where the epipolar derivative of the y-smoothed
    size-3 cost exceeds the threshold, normalised; B_mono's edge scores: distance to Sobel
    edges.  Both against numpy + scipy's exact EDT."""
    import math
    from scipy import ndimage
    from lss_kernels.kernels.filters import gaussian_taps
    scene = make_scene("tiny", seed=2)
    params = Params(max_iterations=1)
    solver = Solver(scene.left, scene.right, scene.d_max, scene.init_ellipse, params=params)
    H, W = solver.H, solver.W
    m = solver.hierarchy.levels[0].margin
    cost = solver.hierarchy.matching_cost.to_numpy()[m:m + H, m:m + W].astype(np.float64)

    g, _, _ = gaussian_taps(OCC_SIGMA, int(math.ceil(4 * OCC_SIGMA)))
    dg = np.zeros_like(g)
    dg[1:-1] = (g[2:] - g[:-2]) / 2.0
    slope = _correlate(_correlate(cost, g, 0), dg[::-1], 1)
    features = np.abs(slope) > OCC_THRESHOLD
    assert 0 < features.sum() < features.size
    dist = ndimage.distance_transform_edt(~features)
    np.testing.assert_allclose(solver.extent.image(solver.costs.b_occ),
                               np.minimum(dist / dist.max(), 1),
                               atol=1e-5)

    for image, edge in ((solver.left, solver.costs.edge_left),
                        (solver.right, solver.costs.edge_right)):
        rgb = solver.extent.image(image).astype(np.float64)
        grey = np.pad(rgb @ [0.299, 0.587, 0.114], 1, mode="edge")
        win = lambda dy, dx: grey[1 + dy:1 + dy + H, 1 + dx:1 + dx + W]
        gx = sum(dx * (2 - abs(dy)) * win(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1))
        gy = sum(dy * (2 - abs(dx)) * win(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1))
        edges = np.hypot(gx, gy) / 8.0 > params.mono_threshold
        assert edges.any()
        dist = ndimage.distance_transform_edt(~edges)
        np.testing.assert_allclose(solver.extent.image(edge), 0.5 * (1 - dist / dist.max()),
                                   atol=1e-5)
    solver.close()
