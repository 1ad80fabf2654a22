"""Flying pixels on hand-made rows: the other surface read along the row, points on either
surface kept, points between them (an SGBM-like smear) counted, occluded pixels no points."""
import numpy as np
import pytest

from lss_kernels.flying import flying_pixels, flying_share, other_surface
from lss_kernels.io import Scene


def _row():
    # background 10 | object 30 (columns 4..7) | background slanted 12, 12.5, ...
    truth = np.array([[10, 10, 10, 10, 30, 30, 30, 30, 12, 12.5, 13, 13.5]], np.float64)
    fg = np.zeros(truth.shape, bool)
    fg[0, 4:8] = True
    return truth, fg


def test_the_other_surface_is_the_nearest_pixel_of_the_other_layer_on_each_side():
    truth, fg = _row()
    left, right = other_surface(truth, fg)
    np.testing.assert_array_equal(left[0, 4:8], 10)       # background left of the object
    np.testing.assert_array_equal(right[0, 4:8], 12)      # and right of it
    np.testing.assert_array_equal(right[0, :4], 30)       # the object, for the background
    assert np.isinf(left[0, :4]).all()                     # nothing of it to the left
    np.testing.assert_array_equal(left[0, 8:], 30)


def test_unknown_truth_is_skipped():
    truth, fg = _row()
    truth[0, 3] = np.inf
    left, _ = other_surface(truth, fg)
    np.testing.assert_array_equal(left[0, 4:8], 10)       # from column 2, past the unknown


def test_points_between_the_surfaces_fly():
    truth, fg = _row()
    points = np.ones(truth.shape, bool)
    # a wrong-side pixel on the background's depth (column 4), one on the object's beyond
    # its edge (column 8): both on a true surface; a smear at 20 and 16: flying
    d = truth.copy()
    d[0, 4] = 10.5
    d[0, 8] = 29.2
    d[0, 3] = 20.0
    d[0, 9] = 16.0
    flying = flying_pixels(d, points, truth, fg)
    assert np.nonzero(flying[0])[0].tolist() == [3, 9]
    # a tolerance of 1 px: 1.0 off is on the surface, 1.5 off is not
    d = truth.copy()
    d[0, 0], d[0, 1] = 11.0, 8.5
    assert np.nonzero(flying_pixels(d, points, truth, fg)[0])[0].tolist() == [1]
    # only the points counted
    assert not flying_pixels(d, np.zeros_like(points), truth, fg).any()


def test_flying_share_counts_the_band_minus_the_occluded():
    H, W = 4, 60
    truth = np.full((H, W), 10.0)
    truth[:, 25:40] = 30.0
    fg = truth > 20
    occ_true = np.zeros((H, W), bool)
    occ_true[:, 5:25] = False
    scene = Scene(name="row", left=np.zeros((H, W, 3), np.float32),
                  right=np.zeros((H, W, 3), np.float32), d_max=40.0, init_ellipse=None,
                  disp_left=truth.astype(np.float32), fg_left=fg, occ_left=occ_true)
    d = truth.copy()
    d[:, 23] = 20.0                                       # a smeared column
    d[:, 22] = 21.0                                       # another, labelled occluded
    occ = np.zeros((H, W), bool)
    occ[:, 22] = True
    share = flying_share(d, occ, scene)
    from lss_kernels.metrics import evaluation_masks
    band = evaluation_masks(scene)["band"]
    assert share["n_points"] == int((band & ~occ).sum())
    assert share["n_flying"] == H                         # column 23, not the occluded 22
    assert share["flying"] == pytest.approx(100.0 * H / share["n_points"])
    no_layers = Scene(**{**scene.__dict__, "fg_left": None})
    assert np.isnan(flying_share(d, occ, no_layers)["flying"])
