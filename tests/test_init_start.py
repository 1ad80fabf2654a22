"""A point's and a box's start (lss_kernels.model.init): the region is widened by ``SPILL``
except towards the left, the object's occluded side, and a box starts from the region under
its centre cut to the box (paper15 scene 2: a start that spills past the object's left edge
carries the foreground over the background there)."""
import numpy as np
import pytest

from lss_kernels import Box, Point


def _widened_spec(mask, radius, left):
    """``mask`` dilated by ``radius`` rows up and down, ``radius`` columns to the right and
    ``left`` to the left (numpy)."""
    rows = mask.copy()
    for k in range(1, radius + 1):
        rows[k:] |= mask[:-k]
        rows[:-k] |= mask[k:]
    out = rows.copy()
    for k in range(1, radius + 1):
        out[:, k:] |= rows[:, :-k]
    for k in range(1, left + 1):
        out[:, :-k] |= rows[:, k:]
    return out


@pytest.mark.parametrize("radius, left", [(1, 0), (3, 0), (3, 1), (2, 2)])
def test_one_sided_widening_matches_the_specification(region, radius, left):
    rng = np.random.default_rng(radius + 10 * left)
    mask = rng.random((24, 40)) < 0.03
    mask[10:14, 18:22] = True
    region.label.from_numpy(np.where(mask, 0, -1).astype(np.int32))
    region.open(0, radius, left)
    np.testing.assert_array_equal(region.label.to_numpy() >= 0,
                                  _widened_spec(mask, radius, left))


def _block_scene(region):
    """d-bar of a near block (cyclopean rows 8-15, columns 10-25, half-disparity 6) on a
    background at 2; the block lies at columns 16-31 of the left view (x_left = x_c + c)."""
    d = np.full((24, 40), 2.0, np.float32)
    d[8:16, 10:26] = 6.0
    region.d.from_numpy(d)
    region.mark_near(20, 1.0)
    block = np.zeros(d.shape, bool)
    block[8:16, 10:26] = True
    return d, block


def test_a_point_region_is_not_widened_to_the_left(region):
    from lss_kernels.model.init import SPILL, SPILL_LEFT
    _, block = _block_scene(region)
    mask = region._point(Point(24.0, 12.0))          # left view: on the block
    assert region.info["seed_cyclopean"] == [18, 12]
    assert (SPILL, SPILL_LEFT) == (6, 0) and region.info["spill_left"] == 0
    want = np.zeros_like(block)
    want[2:22, 10:32] = True                         # 6 px up, down and right, none left
    np.testing.assert_array_equal(mask, want)


def test_a_box_starts_from_the_region_under_its_centre_cut_to_the_box(region):
    _, block = _block_scene(region)
    start, frame = region._box(Box(16.0, 10.0, 30.0, 20.0))   # x_left 16-29: x_c 10-23
    assert frame == "cyclopean"
    want = np.zeros_like(block)
    want[10:20, 10:24] = True              # the widened block (rows 2-21) cut to the box
    np.testing.assert_array_equal(start, want)
    assert region.info["kind"] == "box" and region.info["area"] == want.sum()
    assert "centre" in region.info["from"] and region.info["centre"]["kind"] == "point"


def test_a_box_whose_centre_has_no_match_starts_from_its_ellipse(region):
    from lss_kernels.model.init import box_ellipse
    d, _ = _block_scene(region)
    d[8:16, 14:23] = -1.0                            # no match within 3 px of the centre
    region.d.from_numpy(d)
    box = Box(16.0, 5.0, 32.0, 19.0)
    start, frame = region._box(box)
    assert frame == "left" and start == box_ellipse(box)
    assert region.info["from"] == "the inscribed ellipse" and "no confident" in region.info["why"]


def test_a_box_whose_centre_region_covers_too_little_of_it_starts_from_its_ellipse(
        region, monkeypatch):
    import lss_kernels.model.init as init
    _block_scene(region)
    box = Box(0.0, 0.0, 40.0, 24.0)
    start, frame = region._box(box)                  # the widened block: 440 of 960 px
    assert frame == "cyclopean" and region.info["cover"] == pytest.approx(440 / 960)
    monkeypatch.setattr(init, "MIN_BOX_COVER", 0.5)
    _block_scene(region)
    start, frame = region._box(box)
    assert frame == "left" and start == init.box_ellipse(box)
    assert "46% of it" in region.info["why"]


def test_a_box_on_a_periodic_image_starts_from_its_ellipse(region):
    from lss_kernels.model.init import box_ellipse
    from lss_kernels.checks.periodicity import PERIODIC_AREA, periodic_share
    _block_scene(region)
    x = np.arange(160)
    stripes = np.tile((128 + 100 * np.sin(2 * np.pi * x / 8))[None, :, None], (32, 1, 3))
    assert periodic_share(stripes) >= PERIODIC_AREA
    box = Box(16.0, 10.0, 30.0, 20.0)
    start, frame = region._box(box, periodic=periodic_share(stripes))
    assert frame == "left" and start == box_ellipse(box)
    assert "periodic" in region.info["why"]
    flat = periodic_share(np.zeros((32, 160, 3)))                   # flat: not periodic
    assert flat == 0.0
    start, frame = region._box(box, periodic=flat)
    assert frame == "cyclopean"
