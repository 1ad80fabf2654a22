"""Tests of lss_kernels.viz: exact PNG sizes, the boundary helper against hand-made masks,
the colour-map range.  No Taichi needed."""
import subprocess
import sys

import imageio.v3 as iio
import numpy as np
import pytest

from lss_kernels import viz
from lss_kernels.apps import figures


def _scene(h=37, w=53):
    rng = np.random.default_rng(0)
    left = rng.random((h, w, 3), dtype=np.float32)
    yy, xx = np.mgrid[:h, :w]
    fg = (xx - w / 2) ** 2 / (w / 4) ** 2 + (yy - h / 2) ** 2 / (h / 4) ** 2 < 1
    disp = np.where(fg, 12.0, 4.0).astype(np.float32)
    occ = np.zeros((h, w), bool)
    occ[:, 3:6] = True
    return left, fg, disp, occ


def test_import_and_drawing_leave_pyplot_alone():
    """Importing viz and drawing a figure must not load pyplot (nor select a backend)."""
    code = (
        "import sys; from lss_kernels import viz; "
        "viz.render_figure(viz.new_figure(50, 40)); "
        "assert 'matplotlib.pyplot' not in sys.modules"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_boundary_mask_hand_made():
    m = np.zeros((5, 6), bool)
    m[1:3, 2:4] = True          # a 2x2 square
    expected = np.array([
        [0, 0, 1, 1, 0, 0],
        [0, 1, 1, 1, 1, 0],
        [0, 1, 1, 1, 1, 0],
        [0, 0, 1, 1, 0, 0],
        [0, 0, 0, 0, 0, 0],
    ], bool)
    np.testing.assert_array_equal(viz.boundary_mask(m), expected)


def test_boundary_mask_constant_and_border():
    assert not viz.boundary_mask(np.ones((4, 4), bool)).any()
    assert not viz.boundary_mask(np.zeros((4, 4), bool)).any()
    # A vertical split: only the two columns that touch the split are marked
    m = np.zeros((3, 4), bool)
    m[:, 2:] = True
    expected = np.zeros((3, 4), bool)
    expected[:, 1:3] = True
    np.testing.assert_array_equal(viz.boundary_mask(m), expected)
    # Diagonal neighbours do not count (4-neighbourhood)
    d = np.zeros((3, 3), bool)
    d[0, 0] = True
    b = viz.boundary_mask(d)
    assert b[0, 0] and b[0, 1] and b[1, 0] and not b[1, 1]


def test_thicken():
    m = np.zeros((5, 5), bool)
    m[2, 2] = True
    assert viz.thicken(m, 1).sum() == 9
    assert viz.thicken(m, 0).sum() == 1


def test_colorize_range_and_nonfinite():
    d = np.array([[-5.0, 0.0, 5.0, 10.0, 20.0, np.nan, np.inf]], np.float32)
    rgb = viz.colorize(d, 0, 10)
    assert rgb.dtype == np.uint8 and rgb.shape == (1, 7, 3)
    np.testing.assert_array_equal(rgb[0, 0], rgb[0, 1])     # clipped below
    np.testing.assert_array_equal(rgb[0, 3], rgb[0, 4])     # clipped above
    assert not np.array_equal(rgb[0, 1], rgb[0, 3])
    np.testing.assert_array_equal(rgb[0, 5], [0, 0, 0])
    np.testing.assert_array_equal(rgb[0, 6], [0, 0, 0])
    # The ends of viridis: dark purple at vmin, yellow at vmax
    assert rgb[0, 1, 2] > rgb[0, 1, 1] and rgb[0, 3, 0] > 200 and rgb[0, 3, 1] > 200


def test_colorize_rejects_bad_input():
    with pytest.raises(ValueError, match="disparity"):
        viz.colorize(np.zeros((2, 2, 2)), 0, 1)


def test_occlusion_disparity_rgb_paints_dark_blue():
    _, _, disp, occ = _scene()
    rgb = viz.occlusion_disparity_rgb(disp, occ, 0, 16)
    expected = (np.asarray(viz.OCCLUSION_RGB) * 255 + 0.5).astype(np.uint8)
    assert (rgb[occ] == expected).all()
    assert not (rgb[~occ] == expected).all(axis=1).any()


@pytest.mark.parametrize("shape", [(37, 53), (120, 161), (16, 16)])
def test_saved_pngs_have_input_size(tmp_path, shape):
    left, fg, disp, occ = _scene(*shape)
    p1 = viz.save_disparity_png(tmp_path / "d" / "disparity.png", disp, 0, 16, title="D")
    p2 = viz.save_overlay_png(tmp_path / "overlay.png", left, fg, occ, init_foreground=~fg)
    a, b = iio.imread(p1), iio.imread(p2)
    assert a.shape[:2] == shape and b.shape[:2] == shape


def test_disparity_png_without_vmax_and_with_nan(tmp_path):
    _, _, disp, _ = _scene(64, 80)
    disp[0, 0] = np.nan
    a = iio.imread(viz.save_disparity_png(tmp_path / "x.png", disp))
    assert a.shape[:2] == (64, 80)


def test_overlay_marks_boundary_and_occlusion():
    left, fg, _, occ = _scene()
    left[:] = 0.5
    rgb = viz.overlay_rgb(left, fg, occ, thickness=1)
    edge = viz.boundary_mask(fg)
    red = (rgb[..., 0] > 200) & (rgb[..., 1] < 60)
    np.testing.assert_array_equal(red, edge)
    tinted = occ & ~edge
    assert (rgb[tinted][:, 2] > rgb[tinted][:, 0]).all()


def test_patch_gaussian_eq6():
    d = np.arange(0, 21, dtype=float)
    cost = np.linspace(1.0, 3.0, 21)
    f = figures.patch_gaussian(d, cost, d_p=7.0, sigma_p=2.0)
    assert f[7] == pytest.approx(1.0)            # min C at d_p
    assert f[0] == pytest.approx(3.0 - 2.0 * np.exp(-49 / 8))
    assert f.max() <= 3.0


def test_evolution_frame_and_patch_figure(tmp_path):
    left, fg, disp, occ = _scene()
    snap = dict(consensus_mean=disp, consensus_sigma=np.full(disp.shape, 0.5),
                disparity=disp, occlusion=occ, foreground=fg, initial_foreground=fg)
    a = figures.evolution_frame(left, snap, 16, 3, true_disparity=disp,
                            scores=dict(occ_f1=0.5, bad4=0.1))
    b = figures.evolution_frame(left, snap, 16, 4, true_disparity=disp)
    assert a.shape == b.shape and a.dtype == np.uint8 and a.shape[1] == 5 * 240
    c = figures.evolution_frame(left, snap, 16, 4)
    assert c.shape[1] == 4 * 240
    d = np.arange(0, 17, dtype=float)
    curve = dict(d=d, cost=(d - 8) ** 2 / 64, matching_cost=np.abs(d - 9) / 9, d_p=8.0,
                 sigma_p=2.0, valid=True, mean_D=8.5)
    fig = figures.patch_message_figure([(0, curve), (5, dict(curve, valid=False))], left=left,
                                   patch_box=(10, 10, 9), title="patch")
    out = iio.imread(viz.save_figure(fig, tmp_path / "patch.png"))
    assert out.ndim == 3 and out.shape[0] > 100
