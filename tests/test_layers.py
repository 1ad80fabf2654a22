"""The third layer (in front of the object) and the occlusion rule of ordered layers, against
hand-built cases and their numpy specifications (lss_kernels.reference.layers)."""
import numpy as np
import pytest
import taichi as ti

from lss_kernels.kernels.backend import FieldPool
from lss_kernels.model.layers import (BACKGROUND, FRONT, OBJECT, front_in_left_view,
                                      occlusion_by_layers)
from lss_kernels.reference import layers as ref


def _row(*runs):
    """A one-row scene from runs ``(length, layer, disparity)``, left to right."""
    layers = np.concatenate([np.full(n, k) for n, k, _ in runs])[None, :]
    d = np.concatenate([np.full(n, v, np.float64) for n, _, v in runs])[None, :]
    return d.astype(np.float32), layers


def test_an_object_over_its_background_hides_its_jump(ti_arch):
    # background at 2 px, the object at 6 px from column 10: a jump of 4 hides columns 6..9
    d, layers = _row((10, BACKGROUND, 2.0), (20, OBJECT, 6.0), (10, BACKGROUND, 2.0))
    occ = occlusion_by_layers(d, layers)
    assert np.flatnonzero(occ[0]).tolist() == [6, 7, 8, 9]
    assert np.array_equal(occ, ref.occlusion_by_layers(d, layers))


def test_a_thin_occluder_in_front_of_the_object_hides_its_width_not_its_jump(ti_arch):
    # a rod 4 px wide at 12 px over the object at 6 px: the right camera sees the object
    # again behind the rod's left-view columns, so only 4 object pixels are hidden, left of
    # the rod (columns 12..15); the object hides 4 background pixels (6..9) as before
    d, layers = _row((10, BACKGROUND, 2.0), (8, OBJECT, 6.0), (4, FRONT, 12.0),
                     (8, OBJECT, 6.0), (10, BACKGROUND, 2.0))
    occ = occlusion_by_layers(d, layers)
    assert np.flatnonzero(occ[0]).tolist() == [6, 7, 8, 9, 12, 13, 14, 15]
    assert np.array_equal(occ, ref.occlusion_by_layers(d, layers))


def test_a_wide_occluder_hides_its_whole_jump(ti_arch):
    d, layers = _row((10, BACKGROUND, 2.0), (14, OBJECT, 6.0), (12, FRONT, 11.0),
                     (14, OBJECT, 6.0))
    occ = occlusion_by_layers(d, layers)
    assert np.flatnonzero(occ[0]).tolist() == [6, 7, 8, 9, 19, 20, 21, 22, 23]


def test_only_the_given_occluders_hide_and_a_step_behind_the_object_counts_as_a_layer(ti_arch):
    # a background with a step (far at 2 px, a nearer surface at 5 px from column 20, a
    # layer of its own), and the object at 9 px from column 30
    d, layers = _row((20, BACKGROUND, 2.0), (10, 3, 5.0), (10, OBJECT, 9.0), (4, 3, 5.0))
    occ = occlusion_by_layers(d, layers)
    assert np.flatnonzero(occ[0]).tolist() == [17, 18, 19, 26, 27, 28, 29]
    only_object = occlusion_by_layers(d, layers, occluders=layers == OBJECT)
    assert np.flatnonzero(only_object[0]).tolist() == [26, 27, 28, 29]
    assert np.array_equal(only_object, ref.occlusion_by_layers(d, layers, layers == OBJECT))


def test_occlusion_by_layers_matches_its_specification_on_random_scenes(ti_arch):
    rng = np.random.default_rng(3)
    for _ in range(5):
        layers = np.repeat(rng.integers(0, 3, (6, 8)), 5, axis=1)
        d = (layers * 4.0 + rng.uniform(0, 3, layers.shape)).astype(np.float32)
        occluders = rng.random(layers.shape) < 0.8
        assert np.array_equal(occlusion_by_layers(d, layers, occluders),
                              ref.occlusion_by_layers(d, layers, occluders))


def test_occlusion_by_layers_refuses_bad_arrays(ti_arch):
    with pytest.raises(ValueError, match="disparity"):
        occlusion_by_layers(np.full((2, 3), np.nan), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="layers"):
        occlusion_by_layers(np.zeros((2, 3)), np.zeros((3, 2)))


def test_the_front_layer_is_seen_in_the_left_view_shifted_by_its_disparity():
    front = np.zeros((2, 20), bool)
    front[:, 5:8] = True
    first = np.full((2, 20), 3.0)
    mask, d = front_in_left_view(front, first)
    assert np.flatnonzero(mask[0]).tolist() == [8, 9, 10]
    assert np.all(d[mask] == 6.0) and np.all(d[~mask] == 0.0)


H, W, C = 10, 40, 12


def _volume(c_true):
    """A matching cost whose least candidate at each pixel is ``c_true`` (rising 0.05 a
    candidate away from it)."""
    k = np.arange(1, C + 1, dtype=np.float64)
    return (0.02 + 0.05 * np.abs(k[None, None, :] - c_true[..., None])).astype(np.float32)


@pytest.fixture(scope="module")
def front_layer(ti_arch):
    from lss_kernels.model.front import FrontLayer
    from lss_kernels.model.shapes import GlobalShapes, WeightPlanes
    pool = FieldPool()
    layer = FrontLayer(pool, H, W)
    shapes = GlobalShapes(pool, H, W)
    cost = pool.field(ti.f32, (H, W, C))
    ones, zeros, target, phi = (pool.field(ti.f32, (H, W)) for _ in range(4))
    pool.finalize()
    ones.from_numpy(np.ones((H, W), np.float32))

    def run(volume, theta_1, margin, theta_2=2.0, level=None, near=-1.0):
        for weights, theta in ((WeightPlanes(ones, zeros), theta_1),
                               (WeightPlanes(zeros, ones), theta_2)):
            target.from_numpy(np.broadcast_to(theta, (H, W)).astype(np.float32))
            shapes.fit(weights, target)
        cost.from_numpy(volume)
        phi.from_numpy(np.zeros((H, W), np.float32) if level is None else level)
        layer.capture(cost, C)
        layer.update(cost, C, shapes, phi, near, margin)
        return (layer.front.to_numpy()[:H, :W].astype(bool),
                layer.hidden.to_numpy()[:H, :W].astype(bool))
    yield run
    pool.destroy()


def test_a_rod_in_front_of_the_object_and_the_strips_it_hides(front_layer):
    # the object at c = 5 everywhere, a rod 3 columns wide at c = 8 on columns 20..22
    c_true = np.full((H, W), 5.0)
    c_true[:, 20:23] = 8.0
    c_true[4, 2] = 9.0                     # a stray match: no layer
    volume = _volume(c_true)
    theta_1 = np.full((H, W), 5.0)
    front, hidden = front_layer(volume, theta_1, 1.0)
    assert np.flatnonzero(front[5]).tolist() == [20, 21, 22]
    assert not front[4, 2]
    # hidden: the rod and 3 columns (its jump) on either side
    assert np.flatnonzero(hidden[5]).tolist() == list(range(17, 26))
    f_ref, h_ref = ref.front_layer(volume, theta_1, np.full((H, W), 2.0), 1.0)
    assert np.array_equal(front, f_ref) and np.array_equal(hidden, h_ref)


def test_a_match_that_the_object_explains_as_well_is_not_in_front(front_layer):
    # the same rod, but a flat cost curve: its least candidate is no better than Theta_1
    c_true = np.full((H, W), 5.0)
    c_true[:, 20:23] = 8.0
    volume = _volume(c_true)
    volume[:, 20:23, :] = 0.3
    volume[:, 20:23, 7] = 0.29
    front, hidden = front_layer(volume, np.full((H, W), 5.0), 1.0)
    assert not front.any() and not hidden.any()


def test_only_pixels_near_the_object_can_be_in_front(front_layer):
    # the rod runs on from the object (phi > 0 on columns < 24) into the background: its
    # columns are more than 0.5 (in phi's units) from the object on rows 5 and below
    c_true = np.full((H, W), 5.0)
    c_true[:, 20:23] = 8.0
    volume = _volume(c_true)
    level = np.where(np.arange(H)[:, None] < 5, 1.0, -1.0) * np.ones((1, W))
    front, _ = front_layer(volume, np.full((H, W), 5.0), 1.0, level=level.astype(np.float32),
                           near=-0.5)
    assert front[1:4, 20:23].all() and not front[5:].any()     # row 0: the 3x3 vote
    f_ref, _ = ref.front_layer(volume, np.full((H, W), 5.0), np.full((H, W), 2.0), 1.0,
                               phi=level, near=-0.5)
    assert np.array_equal(front, f_ref)


def test_a_periodic_background_explained_by_theta_2_is_not_in_front(front_layer):
    # stripes: every pixel's cost has a tooth at Theta_2 (c = 2) and, a period on, one in
    # front of the object (c = 9), a little deeper; the background surface explains it
    k = np.arange(1, C + 1, dtype=np.float64)
    curve = 0.3 - 0.28 * np.exp(-(k - 2.0) ** 2) - 0.29 * np.exp(-(k - 9.0) ** 2)
    volume = np.broadcast_to(curve, (H, W, C)).astype(np.float32).copy()
    front, hidden = front_layer(volume, np.full((H, W), 5.0), 1.0)
    assert not front.any() and not hidden.any()
    f_ref, _ = ref.front_layer(volume, np.full((H, W), 5.0), np.full((H, W), 2.0), 1.0)
    assert not f_ref.any()


def test_nothing_in_front_leaves_every_pixel_as_evidence(front_layer):
    rng = np.random.default_rng(0)
    c_true = np.rint(5.0 + rng.uniform(-1.4, 1.4, (H, W)))      # 4, 5 or 6
    front, hidden = front_layer(_volume(c_true), np.full((H, W), 5.0), 1.5)
    assert not front.any() and not hidden.any()
