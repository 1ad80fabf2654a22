"""The paper's scoring protocol on hand-counted rows, against brute force, and on the release."""

import numpy as np
import pytest

from lss_kernels.io import Scene, load_scene
from lss_kernels.metrics import (band_from_foreground, boundary_from_foreground,
                                 evaluation_masks, score, score_arrays)



def row(*values, dtype=bool):
    return np.array([values], dtype=dtype)


# One row of 12 pixels; band = x 0..9 (x 10, 11 outside).
#   x        0  1  2  3  4  5  6  7  8  9 10 11
ROI_BG = row(1, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0)
ROI_FG = row(0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 0, 0)
OCC = row(0, 0, 1, 1, 1, 0, 0, 0, 0, 0, 1, 0)      # true occlusions: x 2, 3, 4 (x 10 off band)
PRED_OCC = row(0, 1, 0, 1, 1, 0, 1, 0, 0, 0, 1, 0)  # in band: x 1, 3, 4, 6
D_TRUE = row(10, 10, 10, 10, 10, 10, 20, 20, 20, 20, 20, 20, dtype=np.float32)
D_PRED = row(10, 14, 99, 99, 99, 14.5, np.nan, 20, np.inf, 25, 0, 0, dtype=np.float32)


def test_hand_counted_row():
    s = score_arrays(D_PRED, PRED_OCC, D_TRUE, OCC, ROI_FG, ROI_BG)
    # TP = {3, 4} = 2, predicted in band = 4, true = 3: P = 1/2, R = 2/3, F1 = 4/7.
    assert (s["n_band"], s["n_true_occ"], s["n_pred_occ"]) == (10, 3, 4)
    assert s["occ_precision"] == pytest.approx(0.5)
    assert s["occ_recall"] == pytest.approx(2 / 3)
    assert s["occ_f1"] == pytest.approx(4 / 7)
    # bad-4.0 over band minus true occlusions = {0, 1, 5, 6, 7, 8, 9} (7 pixels); bad:
    # x 5 (|4.5|), x 6 (NaN), x 8 (inf), x 9 (|5|) = 4; x 1 (|4| exactly) is good.
    assert s["bad4"] == pytest.approx(100 * 4 / 7)


def test_boundary_and_invalid_truth_excluded():
    boundary = row(0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0)   # excludes x 5, 6, 7
    d_true = D_TRUE.copy()
    d_true[0, 0] = np.inf                                # unknown truth: excluded
    s = score_arrays(D_PRED, PRED_OCC, d_true, OCC, ROI_FG, ROI_BG, boundary=boundary)
    # band = {1, 2, 3, 4, 8, 9}; predicted {1, 3, 4}; true {2, 3, 4}; TP 2: P = R = F1 = 2/3.
    assert (s["n_band"], s["n_true_occ"], s["n_pred_occ"]) == (6, 3, 3)
    assert s["occ_f1"] == pytest.approx(2 / 3) and s["occ_precision"] == pytest.approx(2 / 3)
    # bad-4.0 over {1, 8, 9}: x 8, 9 bad.
    assert s["bad4"] == pytest.approx(100 * 2 / 3)


def test_nan_prediction_is_bad():
    d_true = np.full((2, 3), 5.0)
    roi = np.ones((2, 3), bool)
    none = np.zeros((2, 3), bool)
    assert score_arrays(np.full((2, 3), np.nan), none, d_true, none, roi, none)["bad4"] == 100.0
    assert score_arrays(d_true, none, d_true, none, roi, none)["bad4"] == 0.0


def test_degenerate_conventions():
    d = np.zeros((1, 4))
    roi_bg = np.ones((1, 4), bool)
    none = np.zeros((1, 4), bool)
    some = row(0, 1, 0, 0)
    both_empty = score_arrays(d, none, d, none, none, roi_bg)
    assert (both_empty["occ_precision"], both_empty["occ_recall"], both_empty["occ_f1"]) == (1, 1, 1)
    missed = score_arrays(d, none, d, some, none, roi_bg)
    assert (missed["occ_precision"], missed["occ_recall"], missed["occ_f1"]) == (1, 0, 0)
    spurious = score_arrays(d, some, d, none, none, roi_bg)
    assert (spurious["occ_precision"], spurious["occ_recall"], spurious["occ_f1"]) == (0, 1, 0)
    empty_band = score_arrays(d, some, d, some, none, none)
    assert (empty_band["n_band"], empty_band["bad4"], empty_band["occ_f1"]) == (0, 0.0, 1.0)


def test_shape_errors():
    d = np.zeros((3, 4))
    m = np.zeros((3, 4), bool)
    with pytest.raises(ValueError, match=r"^disparity: expected an array of shape \(3, 4\)"):
        score_arrays(np.zeros((4, 3)), m, d, m, m, m)
    with pytest.raises(ValueError, match=r"^occlusion: .* got shape \(3,\)"):
        score_arrays(d, np.zeros(3), d, m, m, m)
    with pytest.raises(ValueError, match=r"^boundary: "):
        score_arrays(d, m, d, m, m, m, boundary=np.zeros((3, 5)))
    with pytest.raises(ValueError, match=r"^radius: "):
        band_from_foreground(m, radius=-1)


def _brute_band(fg, radius):
    """Loop definition: within radius columns of a foreground pixel with a background
    left or right neighbour in the same row."""
    h, w = fg.shape
    boundary = np.zeros_like(fg)
    band = np.zeros_like(fg)
    for y in range(h):
        for x in range(w):
            boundary[y, x] = fg[y, x] and ((x > 0 and not fg[y, x - 1])
                                           or (x < w - 1 and not fg[y, x + 1]))
    for y in range(h):
        for x in range(w):
            band[y, x] = any(boundary[y, xx]
                             for xx in range(max(0, x - radius), min(w, x + radius + 1)))
    return boundary, band


@pytest.mark.parametrize("seed, radius", [(0, 0), (1, 1), (2, 3), (3, 20)])
def test_band_matches_brute_force(seed, radius):
    rng = np.random.default_rng(seed)
    fg = rng.random((7, 30)) < 0.4
    fg[0] = False                                    # a row without a boundary
    fg[1] = True                                     # all foreground: no boundary either
    boundary, band = _brute_band(fg, radius)
    np.testing.assert_array_equal(boundary_from_foreground(fg), boundary)
    roi_fg, roi_bg = band_from_foreground(fg, radius)
    np.testing.assert_array_equal(roi_fg | roi_bg, band)
    np.testing.assert_array_equal(roi_fg, band & fg)
    assert not (roi_fg & roi_bg).any() and not band[:2].any()


def test_band_by_hand():
    fg = row(0, 0, 0, 0, 1, 1, 1, 0, 0, 0, 0, 0)
    assert boundary_from_foreground(fg).nonzero()[1].tolist() == [4, 6]
    roi_fg, roi_bg = band_from_foreground(fg, radius=2)
    assert roi_fg.nonzero()[1].tolist() == [4, 5, 6]
    assert roi_bg.nonzero()[1].tolist() == [2, 3, 7, 8]


def test_score_scene_fallbacks():
    fg = np.zeros((2, 50), bool)
    fg[:, 20:30] = True
    disp = np.where(fg, 20.0, 5.0).astype(np.float32)
    occ = np.zeros_like(fg)
    occ[:, 5:20] = True
    scene = Scene(name="s", left=np.zeros((2, 50, 3)), right=np.zeros((2, 50, 3)), d_max=30,
                  init_ellipse=(25, 1, 5, 1), disp_left=disp, fg_left=fg, occ_left=occ)
    masks = evaluation_masks(scene)
    # No roi files: band from fg_left (boundary x 20 and 29, radius 20 -> x 0..49);
    # no boundary file: nothing excluded.
    assert masks["band"].all() and masks["keep"].all()
    assert masks["true_occ"].sum() == 2 * 15
    perfect = score(disp, occ, scene)
    assert (perfect["occ_f1"], perfect["bad4"]) == (1.0, 0.0)
    # precomputed masks (a caller scoring many predictions of one scene) give the same score
    shifted = np.roll(occ, 3, axis=1)
    assert score(disp + 5, shifted, scene, masks) == score(disp + 5, shifted, scene)
    scene.boundary = boundary_from_foreground(fg)
    assert evaluation_masks(scene)["band"].sum() == 2 * (50 - 6)
    scene.disp_left = None
    with pytest.raises(ValueError, match="no ground truth 'disp_left'"):
        score(disp, occ, scene)


def test_release_band_and_boundary_reproduced(paper15):
    """On scene 2 the release's band and boundary are exactly this module's definitions."""
    scene = load_scene(paper15 / "scene02_bowling2")
    np.testing.assert_array_equal(boundary_from_foreground(scene.fg_left), scene.boundary)
    roi_fg, roi_bg = band_from_foreground(scene.fg_left)
    np.testing.assert_array_equal(roi_fg, scene.roi_fg)
    np.testing.assert_array_equal(roi_bg, scene.roi_bg)


def test_ground_truth_scores_perfectly_on_release(paper15):
    """The two-layer truth (occlusions on the background only) scores perfectly; the release's
    occ_left also marks some foreground pixels, which the protocol counts as false positives."""
    scene = load_scene(paper15 / "scene03_flowerpots")
    s = score(scene.disp_left, scene.occ_left & ~scene.fg_left, scene)
    assert (s["occ_f1"], s["occ_precision"], s["occ_recall"], s["bad4"]) == (1.0, 1.0, 1.0, 0.0)
    assert s["n_true_occ"] > 0 and s["n_band"] > s["n_true_occ"]
    assert score(scene.disp_left, scene.occ_left, scene)["occ_precision"] < 1.0
    flat = score(np.zeros_like(scene.disp_left), np.zeros_like(scene.occ_left), scene)
    assert flat["occ_f1"] == 0.0 and flat["bad4"] == 100.0
