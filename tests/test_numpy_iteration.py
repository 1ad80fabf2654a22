"""The numpy specification of one iteration against Solver.step().

Tolerances: the kernels work in float32 (eps 1.2e-7), the numpy specification in float64, from
the same float32 state.  phi is O(0.01-0.3) here (PHI_SCALE 0.01 x a distance of a few pixels)
and one step changes it by dt x O(1) x 1/pi; the 29-tap Gaussian-derivative filters and the
per-pixel sums keep float32 round-off near 1e-6 of the values, so 1e-4 (absolute, phi) leaves a
factor ~10 of margin after several iterations (observed: ~1e-6 after one, <1e-4 after six).
Theta comes from float32 normal equations whose condition number (normalised basis, squared
precision weights) is ~1e3-1e4, so its relative error is ~1e-4; the tolerance is 3e-3 of the
largest coefficient.  The consensus is a sum of float32 reciprocals: precision rtol 1e-5, mean
1e-3 cyclopean pixels; the set of pixels with no valid patch must match exactly.
"""
import numpy as np
import pytest

from lss_kernels.reference import iteration as npi
from lss_kernels.reference import kernels as ref
from lss_kernels.apps.bench import synthetic_pair
from lss_kernels.params import Params

H, W, D_MAX = 40, 56, 16
# the start is the scenes' ellipse as given: a region found in it (refine_ellipse) has rows of
# constant phi beside its flat edges, where dphi/dx is a float32 or float64 round-off of zero
# and the ray cast's direction the sign of that round-off (0.003 of phi seen at 61 pixels)
PARAMS = Params(reinit_every=3, max_iterations=1000, stop_shift=0.0, refine_ellipse=False)


def _check(kernel, spec, theta_rtol=3e-3, phi_atol=1e-4):
    phi_k, phi_n = kernel.phi, spec.phi
    assert np.abs(phi_k - phi_n).max() < phi_atol
    # the foreground itself: signs may only differ where |phi| is at round-off level
    differ = (phi_k > 0) != (phi_n > 0)
    assert np.all(np.abs(phi_n[differ]) < phi_atol)
    scale = max(1.0, np.abs(spec.theta).max())
    assert np.abs(kernel.theta - spec.theta).max() < theta_rtol * scale
    pk, pn = kernel.extra["precision"], spec.extra["precision"]
    np.testing.assert_array_equal(pk > 0, pn > 0)
    np.testing.assert_allclose(pk, pn, rtol=1e-5, atol=0)
    mk, mn = kernel.extra["consensus_mean"], spec.extra["consensus_mean"]
    assert np.abs(mk - mn).max() < 1e-3


@pytest.fixture(scope="module")
def solver(ti_arch):
    from lss_kernels.solver import Solver
    left, right, init = synthetic_pair(W, H, D_MAX, seed=1)
    s = Solver(left, right, D_MAX, init, params=PARAMS)
    yield s
    s.close()


def test_one_and_several_iterations_match_the_kernels(solver):
    """Six kernel iterations (the first: no prior, every patch valid; then the prior,
    validity and two re-initialisations), each against numpy's iteration from the kernels'
    own state before it.  Each step is compared, not six chained ones: a pixel whose phi
    ends a step at round-off level may take either sign in float32 and float64, and the next
    signed-distance re-initialisation turns that into a pixel of distance for its
    neighbours (PHI_SCALE x 1 = 0.01 per pixel; 0.06 seen after six chained iterations when
    a change of rounding order in the messages moved Theta's fit by 3e-4): the chain would
    test round-off luck, not the iteration."""
    start = npi.state_from_solver(solver)
    assert start.phi.shape == (H, W) and start.c_max == 8
    assert [c.shape for c in start.costs] == [(H, W, 8)] * 3

    # the first iteration, at the tighter tolerances of a single step from the set-up
    solver.step()
    after_one = npi.state_from_solver(solver)
    spec, seconds = npi.iteration(start, PARAMS)
    assert set(seconds) == set(npi.STAGES)
    _check(after_one, spec, theta_rtol=1e-3, phi_atol=2e-5)
    assert spec.extra["flipped"] == solver.history[-1]["flipped"]

    # five more (prior, validity, re-initialisations at 3 and 6), each from the kernels' state
    state = after_one
    for _ in range(5):
        spec, _ = npi.iteration(state, PARAMS)
        solver.step()
        state = npi.state_from_solver(solver)
        _check(state, spec)
        np.testing.assert_allclose(state.D, spec.D, atol=5e-2)
    assert state.iteration == spec.iteration == 6


def test_patch_sums_are_transposes():
    """Upward sums over a patch and downward sums over the patches containing a pixel are
    adjoint; for an even size they are different boxes."""
    rng = np.random.default_rng(0)
    a, b = rng.random((12, 15)), rng.random((12, 15))
    for size in (3, 9, 18):
        lhs = (ref.box_sum(a, size) * b).sum()
        rhs = (a * ref.patches_containing(b, size)).sum()
        assert lhs == pytest.approx(rhs, rel=1e-12)
    imp = np.zeros((30, 30))
    imp[15, 15] = 1.0
    ys, xs = np.nonzero(ref.patches_containing(imp, 18))
    # the patch centred on 15 covers 6 .. 23
    assert (ys.min(), ys.max(), xs.min(), xs.max()) == (6, 23, 6, 23)


def test_median_and_reinitialisation():
    rng = np.random.default_rng(1)
    phi = rng.standard_normal((9, 11))
    med = ref.median_filter(phi, 7)
    pad = np.pad(phi, 3, mode="symmetric")
    assert med[4, 5] == np.median(pad[4:11, 5:12])
    assert med[0, 0] == np.median(pad[0:7, 0:7])
    mask = np.zeros((20, 20))
    mask[5:15, 5:15] = 1.0
    sd = ref.reinitialise(np.where(mask > 0, 1.0, -1.0), 0.01)
    assert np.array_equal(sd > 0, mask > 0)
    assert sd[10, 10] == pytest.approx(0.01 * (5 - 0.5))   # 5 pixels to the nearest outside
    assert sd[0, 10] == pytest.approx(-0.01 * (5 - 0.5))


def test_one_iteration_at_a_width_of_partial_lane_blocks(fresh_taichi):
    """At a width of 61 pixels (7 blocks of 8 lanes and a partial one) the first iteration's
    phi, its foreground and Theta match the specification as at 56 pixels."""
    from lss_kernels.solver import Solver
    left, right, init = synthetic_pair(61, 30, D_MAX, seed=2)
    solver = Solver(left, right, D_MAX, init, params=PARAMS)
    start = npi.state_from_solver(solver)
    solver.step()
    kernel = npi.state_from_solver(solver)
    spec, _ = npi.iteration(start, PARAMS)
    assert np.abs(kernel.phi - spec.phi).max() < 2e-5
    assert np.abs(kernel.phi - start.phi).max() > 1e-3          # the step moved phi
    differ = (kernel.phi > 0) != (spec.phi > 0)
    assert np.all(np.abs(spec.phi[differ]) < 2e-5)
    scale = max(1.0, np.abs(spec.theta).max())
    assert np.abs(kernel.theta - spec.theta).max() < 1e-3 * scale
    solver.close()


@pytest.mark.parametrize("switch", [{"subpixel_messages": False}, {"narrow_band": 0.0},
                                    {"message_ambiguity": 0.9}, {"background_sweep": 0.0}],
                         ids=["integer_argmin", "no_narrow_band", "message_ambiguity",
                              "no_background_sweep"])
def test_the_papers_switches_match_the_specification(fresh_taichi, switch):
    """The iteration with the switches that ``Params.paper()`` turns to the paper's method
    (Eq. 5's integer argmin; Eq. 2's step everywhere, no narrow band) and with the messages
    weighted by their distinctness (a periodic pair's): three iterations, each against
    numpy's from the kernels' own state before it."""
    from lss_kernels.solver import Solver
    params = PARAMS.replace(**switch)
    left, right, init = synthetic_pair(W, H, D_MAX, seed=1)
    solver = Solver(left, right, D_MAX, init, params=params)
    state = npi.state_from_solver(solver)
    moved = 0.0
    for _ in range(3):
        spec, _ = npi.iteration(state, params)
        default, _ = npi.iteration(state, PARAMS)      # what the switch changes
        moved = max(moved, np.abs(spec.phi - default.phi).max(),
                    np.abs(spec.extra["consensus_mean"] - default.extra["consensus_mean"]).max(),
                    np.abs(spec.theta - default.theta).max())
        solver.step()
        state = npi.state_from_solver(solver)
        _check(state, spec)
    assert moved > 1e-3
    solver.close()


@pytest.mark.parametrize("width", [56, 61])
def test_a_single_patch_level_matches_the_specification(fresh_taichi, width):
    """With one level of patches the pixels' consensus reads that level's relays one patch
    centre beyond the image on every side: the level keeps that margin.  Three iterations
    (the prior and validity enter at the second, phi is re-initialised at the third); at 61
    pixels the last block of lanes is partial.  That scene's initial phi is symmetric about
    column 25, where dphi/dx is -0.0 and the occlusion ray cast's direction is a matter of
    the sign of zero (kernel and specification differ there by 3 px of delta_theta), so phi
    is compared only at 56; the consensus and Theta at both."""
    from lss_kernels.solver import Solver
    params = PARAMS.replace(patch_sizes=(3,))
    left, right, init = synthetic_pair(width, 30 if width == 61 else H, D_MAX,
                                       seed=2 if width == 61 else 1)
    solver = Solver(left, right, D_MAX, init, params=params)
    spec = npi.state_from_solver(solver)
    for _ in range(3):
        solver.step()
        spec, _ = npi.iteration(spec, params)
    kernel = npi.state_from_solver(solver)
    pk, pn = kernel.extra["precision"], spec.extra["precision"]
    np.testing.assert_array_equal(pk > 0, pn > 0)
    np.testing.assert_allclose(pk, pn, rtol=1e-5, atol=0)
    assert np.abs(kernel.extra["consensus_mean"] - spec.extra["consensus_mean"]).max() < 1e-3
    scale = max(1.0, np.abs(spec.theta).max())
    assert np.abs(kernel.theta - spec.theta).max() < 3e-3 * scale
    if width == 56:
        _check(kernel, spec)
    solver.close()


@pytest.mark.slow
def test_the_background_sweep_sets_the_same_plane(fresh_taichi):
    """A textured object 11 px in front of a dark background of 8 grey levels under noise,
    the start inside the object: the first iteration's plane sweep sets Theta_2 to the same
    plane in the kernels and the specification, and phi moves alike.  The start's centre lies
    off the pixel grid's columns: on a column of mirror symmetry phi's x-derivative is at
    round-off level, its sign (the ray cast's direction) that of round-off, and the plane's
    jump, unlike a surface fitted over the object, is cast there."""
    from lss_kernels.scenes import make_scene
    from lss_kernels.solver import Solver
    scene = make_scene(None, seed=0, width=96, height=72, d_fg=14.0, d_bg=3.0,
                       ellipse=(48, 36, 18, 15), texture_fg="random",
                       texture_bg="low_contrast", noise=0.012, init_scale=0.8,
                       init_shift=(0.21, -0.11))
    solver = Solver(scene.left, scene.right, scene.d_max, scene.init_ellipse, params=PARAMS)
    start = npi.state_from_solver(solver)
    solver.step()
    kernel = npi.state_from_solver(solver)
    spec, _ = npi.iteration(start, PARAMS)
    plane = spec.extra["plane"]
    assert plane is not None and abs(2 * plane - solver.offset - 3.0) < 1.0
    assert solver.history[-1]["background_plane"] == pytest.approx(2 * plane - solver.offset,
                                                                   abs=2e-3)
    np.testing.assert_allclose(kernel.theta[1], [0, 0, 0, 0, 0, plane], atol=1e-3)
    assert np.abs(kernel.theta - spec.theta).max() < 1e-3 * max(1.0, np.abs(spec.theta).max())
    assert np.abs(kernel.phi - start.phi).max() > 1e-3          # the step moved phi
    assert np.abs(kernel.phi - spec.phi).max() < 2e-5
    solver.close()
