"""Surface plus parallax (lss_kernels.model.refine): kernels against the numpy specification,
non-quadratic layers recovered, nothing carried across a boundary, and the solver's outputs."""
import numpy as np
import pytest
import taichi as ti

from lss_kernels import Params
from lss_kernels.params import REFINE_SUPPORT
from lss_kernels.kernels.backend import FieldPool
from lss_kernels.model.refine import LayerRefinement
from lss_kernels.reference import refine as after


def _texture(rng, H, W, cell=2.0):
    """A smooth random colour texture, sampled at real u along the row."""
    grid = rng.random((H, int(W / cell) + 4, 3))

    def sample(y, u):
        g = np.clip(u / cell + 1.0, 0, grid.shape[1] - 1.001)
        i = np.floor(g).astype(int)
        t = (g - i)[..., None]
        return (1 - t) * grid[y, i] + t * grid[y, i + 1]
    return sample


def render(d_fg, d_bg, fg, seed=0):
    """A rectified pair seeing two layers with left-view disparities ``d_fg``, ``d_bg``
    (``(H, W)`` arrays, any shape of surface) and the left-view foreground ``fg``; the right
    image by splatting both layers finely with a z-buffer (the nearer disparity wins).
    Returns left, right and the true occlusion."""
    H, W = fg.shape
    rng = np.random.default_rng(seed)
    tex = [_texture(rng, H, W), _texture(rng, H, W)]
    x = np.arange(W, dtype=np.float64)
    left = np.empty((H, W, 3))
    right = np.zeros((H, W, 3))
    occ = np.zeros((H, W), bool)
    for y in range(H):
        left[y] = np.where(fg[y][:, None], tex[0](y, x), tex[1](y, x))
        depth = np.full(W, -np.inf)
        u = np.arange(0, W - 1, 0.05)
        for j, d in enumerate((d_bg, d_fg)):
            layer = fg if j == 1 else ~fg
            inside = np.interp(u, x, layer[y].astype(float)) > 0.5
            du = np.interp(u, x, d[y])
            xr = np.round(u - du).astype(int)
            ok = inside & (xr >= 0) & (xr < W)
            for ur, r, dv in zip(u[ok], xr[ok], du[ok]):
                if dv >= depth[r]:
                    depth[r] = dv
                    right[y, r] = tex[1 - j](y, ur)
        # occluded: the right camera sees a nearer surface at x - d
        d_left = np.where(fg[y], d_fg[y], d_bg[y])
        xr = np.round(x - d_left).astype(int)
        seen = (xr >= 0) & (depth[np.clip(xr, 0, W - 1)] > d_left + 0.5)
        occ[y] = seen
    # 8-bit levels, as a camera gives: the census compares grey values that f32 (kernels)
    # and f64 (numpy) then order alike
    quantise = lambda img: (np.round(img * 255) / 255).astype(np.float32)
    return quantise(left), quantise(right), occ


def run_kernels(left, right, surface, fg, occ, d_max, passes, ratio=0.9, support=0.0,
                evidence=False):
    H, W = surface.shape
    pool = FieldPool()
    L, R = pool.vector(3, ti.f32, (H, W)), pool.vector(3, ti.f32, (H, W))
    S, F, O = (pool.field(ti.f32, (H, W)), pool.field(ti.i32, (H, W)),
               pool.field(ti.i32, (H, W)))
    refinement = LayerRefinement(pool, H, W, passes, ratio, support)
    pool.finalize()
    L.from_numpy(left)
    R.from_numpy(right)
    S.from_numpy(surface.astype(np.float32))
    F.from_numpy(fg.astype(np.int32))
    O.from_numpy(occ.astype(np.int32))
    refinement.run(L, R, S, F, O, d_max)
    out = refinement.extent.image(refinement.surface)
    if evidence:
        out = (out, refinement.extent.image(refinement.match),
               refinement.extent.image(refinement.peak_ratio))
    pool.destroy()
    return out


def two_layers(H=48, W=96, jump=(30.0, 8.0)):
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    fg = (np.abs(x - 55) < 18) & (np.abs(y - H / 2) < 14)
    return np.full((H, W), jump[0]), np.full((H, W), jump[1]), fg


def test_kernels_match_the_numpy_specification(ti_arch):
    d_fg, d_bg, fg = two_layers()
    d_fg = d_fg + 0.05 * (np.arange(96) - 55)[None]          # a slanted object
    left, right, occ = render(d_fg, d_bg, fg, seed=1)
    surface = np.where(fg, 29.0, 9.5)                          # off by a pixel or so
    passes = ((5, 3, 2), (2, 2, 1))
    got = run_kernels(left, right, surface, fg, occ, 40.0, passes, support=0.2)
    want = after.refine_layers(left, right, surface, fg, occ, 40.0, passes, 0.9, 0.2)
    # f32 prefix sums against f64 box sums: a few thousandths of a pixel; a near-tie of two
    # candidates may rank differently at a rare pixel
    close = np.abs(got - want) < 0.01
    assert close.mean() > 0.995, np.abs(got - want).max()
    assert np.abs(got - want).mean() < 1e-3


def test_the_last_pass_evidence_matches_the_numpy_specification(ti_arch):
    """The match and peak ratio that :mod:`lss_kernels.confidence` reads."""
    d_fg, d_bg, fg = two_layers()
    left, right, occ = render(d_fg, d_bg, fg, seed=2)
    surface = np.where(fg, 29.0, 9.5)
    passes = ((5, 3, 2), (2, 2, 1))
    _, match, ratio = run_kernels(left, right, surface, fg, occ, 40.0, passes, support=0.2,
                                  evidence=True)
    _, want_match, want_ratio = after.refine_with_evidence(left, right, surface, fg, occ, 40.0,
                                                           passes, 0.9, 0.2)
    assert (np.abs(match - want_match) < 0.01).mean() > 0.995
    assert (np.abs(ratio - want_ratio) < 1e-3).mean() > 0.995
    assert ((ratio > 0) & (ratio <= 1)).all()
    # the textured pair's distinct matches are its true disparities, within the half pixel
    # of a parabola's vertex on a census cost
    distinct = (ratio < 0.9) & ~occ
    assert distinct.mean() > 0.5
    truth = np.where(fg, d_fg, d_bg)
    assert np.median(np.abs(match - truth)[distinct]) < 0.5


def test_a_surface_outside_the_searched_range_is_clamped_first(ti_arch):
    """A quadratic may leave [0, d_max] where its layer lies (paper15 scene 2's background
    does): the sweep starts from the surface clamped to the range, so a background at 6 px
    whose surface says -40 px (all its candidates below 0 otherwise) is found; NaN and
    infinity count as 0."""
    d_fg, d_bg, fg = two_layers(jump=(30.0, 6.0))
    left, right, occ = render(d_fg, d_bg, fg, seed=4)
    surface = np.where(fg, 30.0, -40.0)
    surface[0, :3] = [np.nan, np.inf, -np.inf]
    passes = Params().refine_passes
    got = run_kernels(left, right, surface, fg, occ, 40.0, passes)
    clamped = np.clip(np.where(np.isfinite(surface), surface, 0.0), 0.0, 40.0)
    np.testing.assert_array_equal(got, run_kernels(left, right, clamped, fg, occ, 40.0, passes))
    x = np.arange(fg.shape[1])[None]
    seen = ~occ & ~fg & (x >= 40)
    assert np.abs(got - 6.0)[seen].mean() < 0.5
    want = after.refine_layers(left, right, surface, fg, occ, 40.0, passes, 0.9)
    assert np.abs(got - want).mean() < 1e-3


def test_a_sinusoidal_bump_and_a_sphere_are_recovered(ti_arch):
    """Layers no quadratic describes: the background carries a sinusoidal bump of 3 px, the
    object is a sphere cap 5 px deep; started from flat surfaces, the refinement recovers
    both to <= 0.5 px mean error over the pixels both cameras see."""
    H, W = 64, 128
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    d_bg = 10.0 + 3.0 * np.sin(2 * np.pi * x / 60.0) * np.cos(2 * np.pi * y / 80.0)
    r2 = ((x - 70) / 24.0) ** 2 + ((y - 32) / 20.0) ** 2
    fg = r2 < 1.0
    d_fg = 28.0 + 5.0 * np.sqrt(np.clip(1.0 - r2, 0.0, 1.0))
    left, right, occ = render(d_fg, d_bg, fg, seed=2)
    surface = np.where(fg, 30.0, 10.0)
    got = run_kernels(left, right, surface, fg, occ, 48.0, Params().refine_passes)
    truth = np.where(fg, d_fg, d_bg)
    seen = ~occ & (x >= 40)              # the right image holds x - d for x >= d_max
    before = np.abs(surface - truth)[seen].mean()
    err = np.abs(got - truth)[seen]
    assert err.mean() <= 0.5 and err.mean() < before / 2, (err.mean(), before)


def test_nothing_crosses_a_large_jump(ti_arch):
    """A 40 px jump, both layers' surfaces off by 2 px in opposite directions: every pixel
    that both cameras see ends within 1 px of its own layer's disparity, the boundary
    columns included (a window mixing the layers would pull them 40 px)."""
    d_fg, d_bg, fg = two_layers(jump=(48.0, 8.0))
    left, right, occ = render(d_fg, d_bg, fg, seed=3)
    surface = np.where(fg, 46.0, 10.0)
    got = run_kernels(left, right, surface, fg, occ, 64.0, Params().refine_passes)
    truth = np.where(fg, d_fg, d_bg)
    x = np.arange(96)[None].repeat(48, 0)
    seen = ~occ & (x >= 64)
    edge = seen & (fg != np.roll(fg, 1, axis=1)) | (fg != np.roll(fg, -1, axis=1))
    assert np.abs(got - truth)[seen].max() <= 1.0
    assert np.abs(got - truth)[edge & seen].max() <= 1.0


def test_no_evidence_keeps_the_surface(ti_arch):
    """A textureless pair has no distinct match anywhere: the surface comes back as it was."""
    H, W = 24, 48
    flat = np.full((H, W, 3), 0.5, np.float32)
    surface = np.full((H, W), 7.25)
    fg = np.zeros((H, W), bool)
    got = run_kernels(flat, flat, surface, fg, fg, 16.0, ((4, 2, 2),))
    np.testing.assert_allclose(got, surface, atol=1e-6)


def dark_flat_background(seed, H=64, W=128):
    """A textured object at 30 px before a background at 10 px that is flat and dark (grey
    level 0.1) under camera noise of 1 %: the background's few distinct matches are noise.
    Returns left, right, fg, occlusion."""
    fg = np.zeros((H, W), bool)
    fg[16:48, 60:100] = True
    left, right, occ = render(np.full((H, W), 30.0), np.full((H, W), 10.0), fg, seed=seed)
    seen_fg = np.roll(fg, -30, axis=1)                 # where the right image shows it
    left[~fg] = 0.1
    right[~seen_fg] = 0.1
    rng = np.random.default_rng(seed + 10)
    noisy = lambda img: (np.round(np.clip(img + rng.normal(0, 0.01, img.shape), 0, 1) * 255)
                         / 255).astype(np.float32)
    return noisy(left), noisy(right), fg, occ


@pytest.mark.parametrize("seed", [0, 2])
def test_a_dark_flat_layer_with_few_matches_keeps_its_surface(ti_arch, seed):
    """The background's correct surface survives its noise matches with ``REFINE_SUPPORT``
    (mean error < 0.1 px, under 3 % of its pixels off by > 1 px); averaging every match,
    however few (support 0), moves it at least twice as far."""
    left, right, fg, occ = dark_flat_background(seed)
    surface = np.where(fg, 30.0, 10.0)
    seen = ~occ & ~fg & (np.arange(fg.shape[1])[None] >= 48)
    errors = {}
    for support in (0.0, REFINE_SUPPORT):
        got = run_kernels(left, right, surface, fg, occ, 48.0, Params().refine_passes,
                          support=support)
        errors[support] = np.abs(got - 10.0)[seen]
    kept = errors[REFINE_SUPPORT]
    assert kept.mean() < 0.1 and (kept > 1.0).mean() < 0.03, (kept.mean(), kept.max())
    assert errors[0.0].mean() > 2 * kept.mean(), (errors[0.0].mean(), kept.mean())


def test_params_refine_fields_are_validated():
    with pytest.raises(ValueError, match="refine_passes"):
        Params(refine_passes=((24, 9),))
    with pytest.raises(ValueError, match="refine_passes"):
        Params(refine_passes=((0, 9, 8),))
    with pytest.raises(ValueError, match="params.refine"):
        Params(refine=1)


@pytest.mark.parametrize("refine", [True, False])
def test_solve_writes_the_refined_map_and_the_surface(ti_arch, tmp_path, capsys, refine):
    """``lss solve``: disparity.pfm is the refined map, surface.pfm the two quadratics;
    ``--no-refine`` makes them one; summary.json records the refinement."""
    import json
    from lss_kernels.apps.cli import main
    from lss_kernels.io import read_pfm
    out = tmp_path / "out"
    args = ["solve", "--preset", "tiny", "--out", str(out), "--arch", ti_arch,
            "--max-iterations", "30", "--quiet"] + ([] if refine else ["--no-refine"])
    assert main(args) == 0, capsys.readouterr().err
    disparity, surface = read_pfm(out / "disparity.pfm"), read_pfm(out / "surface.pfm")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["refinement"]["enabled"] is refine
    assert summary["refinement"]["passes"] == [list(p) for p in Params().refine_passes]
    assert np.isfinite(disparity).all() and np.isfinite(surface).all()
    if refine:
        assert summary["refinement"]["seconds"] > 0
        assert not np.array_equal(disparity, surface)
    else:
        np.testing.assert_array_equal(disparity, surface)
