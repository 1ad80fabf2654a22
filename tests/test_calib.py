"""Calibration, metric depth and point clouds: calib.txt read against hand-written files,
depth and points against the pinhole formulas, PLY files read back by ``plyfile``, and
``lss solve --calib`` end to end."""
import json

import numpy as np
import pytest
from plyfile import PlyData

from lss_kernels.apps.cli import main
from lss_kernels.calib import Calibration, read_calib
from lss_kernels.cloud import cloud, read_ply, select, write_ply
from lss_kernels.io import read_pfm

MIDDLEBURY = """cam0=[3997.684 0 1176.728; 0 3997.684 1011.728; 0 0 1]
cam1=[3997.684 0 1307.839; 0 3997.684 1011.728; 0 0 1]
doffs=131.111
baseline=193.001
width=2964
height=1988
ndisp=280
isint=0
vmin=31
vmax=257
dyavg=0.918
dymax=1.516
"""


def calib_file(tmp_path, focal=100.0, cx=60.0, cy=45.0, doffs=4.0, baseline=0.1,
               width=128, height=96, name="calib.txt"):
    path = tmp_path / name
    path.write_text(f"cam0=[{focal} 0 {cx}; 0 {focal} {cy}; 0 0 1]\n"
                    f"cam1=[{focal} 0 {cx + doffs}; 0 {focal} {cy}; 0 0 1]\n"
                    f"doffs={doffs}\nbaseline={baseline}\nwidth={width}\nheight={height}\n"
                    f"ndisp=32\n")
    return path


def test_reads_a_middlebury_calib(tmp_path):
    path = tmp_path / "calib.txt"
    path.write_text(MIDDLEBURY)
    c = read_calib(path)
    assert (c.focal, c.baseline, c.cx, c.cy, c.width, c.height) == (
        3997.684, 193.001, 1176.728, 1011.728, 2964, 1988)
    assert c.doffs == pytest.approx(131.111)


def test_depth_is_focal_times_baseline_over_disparity_plus_doffs():
    c = Calibration(focal=500.0, baseline=0.2, doffs=10.0)
    d = np.array([[0.0, 10.0, 90.0], [-10.0, -20.0, np.nan]], np.float32)
    z = c.depth(d)
    assert z.dtype == np.float32
    np.testing.assert_allclose(z[0], [10.0, 5.0, 1.0], rtol=1e-7)
    assert np.isinf(z[1]).all()           # at infinity, behind the cameras, unknown


def test_points_follow_the_pinhole_model():
    c = Calibration(focal=100.0, baseline=1.0, cx=2.0, cy=1.0)
    d = np.full((3, 5), 50.0, np.float32)             # Z = 2 everywhere
    d[0, 0] = 0.0                                      # at infinity: no point
    xyz, kept = c.points(d)
    assert kept.sum() == 14 and not kept[0, 0]
    ys, xs = np.nonzero(kept)
    np.testing.assert_allclose(xyz[:, 2], 2.0)
    np.testing.assert_allclose(xyz[:, 0], (xs - 2.0) * 2.0 / 100.0, rtol=1e-6)
    np.testing.assert_allclose(xyz[:, 1], (ys - 1.0) * 2.0 / 100.0, rtol=1e-6)
    # without a principal point: the image's centre
    centre = Calibration(focal=100.0, baseline=1.0)
    assert centre.principal_point((3, 5)) == (2.0, 1.0)


def test_a_plane_stays_a_plane():
    """A fronto-parallel plane of constant disparity gives points of one depth; a slanted
    disparity plane d = a x + b (a plane in space too) gives coplanar points."""
    c = Calibration(focal=300.0, baseline=0.5, cx=20.0, cy=10.0, doffs=2.0)
    y, x = np.mgrid[0:20, 0:40].astype(np.float32)
    xyz, _ = c.points(0.3 * x + 12.0)
    centred = xyz - xyz.mean(axis=0)
    singular = np.linalg.svd(centred.astype(np.float64), compute_uv=False)
    assert singular[-1] < 1e-5 * singular[0]


def object_and_strip():
    """A 6 x 8 left view: a 3 x 3 object and the 3 x 2 strip it hides to its left."""
    fg = np.zeros((6, 8), bool)
    fg[2:5, 3:6] = True
    occ = np.zeros((6, 8), bool)
    occ[2:5, 1:3] = True
    return fg, occ


def test_selections_and_the_cloud_round_trip_through_plyfile(tmp_path):
    fg, occ = object_and_strip()
    H, W = fg.shape
    assert select("object", fg, occ).sum() == 9
    assert select("all", fg, occ).sum() == H * W - 6
    assert select("background", fg, occ).sum() == H * W - 6 - 9
    with pytest.raises(ValueError, match=r"^which: expected one of all, object, background, "
                                         r"got 'wall'$"):
        select("wall", fg, occ)
    rng = np.random.default_rng(0)
    image = rng.random((H, W, 3)).astype(np.float32)
    d = np.where(fg, 20.0, 5.0).astype(np.float32)
    c = Calibration(focal=50.0, baseline=2.0)
    points = cloud(c, d, image, fg.astype(np.uint8), select("all", fg, occ))
    path = write_ply(tmp_path / "cloud.ply", points)
    ply = PlyData.read(str(path))
    assert ply.byte_order == "<" and not ply.text
    names = [p.name for p in ply["vertex"].properties]
    assert names == ["x", "y", "z", "red", "green", "blue", "layer"]
    back = read_ply(path)
    np.testing.assert_array_equal(back["xyz"], points["xyz"])
    np.testing.assert_array_equal(back["rgb"], np.round(image[~occ] * 255).astype(np.uint8))
    np.testing.assert_array_equal(back["layer"], fg[~occ].astype(np.uint8))
    np.testing.assert_allclose(back["xyz"][back["layer"] == 1, 2], 5.0)
    np.testing.assert_allclose(back["xyz"][back["layer"] == 0, 2], 20.0)


def test_points_carry_their_confidence_and_min_confidence_keeps_the_sure_ones(tmp_path):
    fg, occ = object_and_strip()
    H, W = fg.shape
    conf = np.linspace(0, 1, H * W, dtype=np.float32).reshape(H, W)
    conf[occ] = 0
    # min_confidence leaves out the pixels below it, whichever the selection
    keep = select("object", fg, occ, conf, 0.5)
    np.testing.assert_array_equal(keep, fg & ~occ & (conf >= 0.5))
    np.testing.assert_array_equal(select("all", fg, occ, conf, 0.0), ~occ)
    for bad in (-0.1, 1.5, True, "0.3"):
        with pytest.raises(ValueError, match=r"^min_confidence: expected a number in \[0, 1\]"):
            select("all", fg, occ, conf, bad)
    with pytest.raises(ValueError, match=r"^confidence: expected an array of shape \(6, 8\)"):
        select("all", fg, occ, None, 0.2)
    c = Calibration(focal=50.0, baseline=2.0)
    d = np.where(fg, 20.0, 5.0).astype(np.float32)
    image = np.zeros((H, W, 3), np.uint8)
    points = cloud(c, d, image, fg.astype(np.uint8), select("all", fg, occ), conf)
    path = write_ply(tmp_path / "cloud.ply", points)
    names = [p.name for p in PlyData.read(str(path))["vertex"].properties]
    assert names == ["x", "y", "z", "red", "green", "blue", "layer", "confidence"]
    np.testing.assert_array_equal(read_ply(path)["confidence"], conf[~occ])
    with pytest.raises(ValueError, match=r"^confidence: expected an array of shape \(6, 8\)"):
        cloud(c, d, image, fg.astype(np.uint8), select("all", fg, occ), conf[:2])


def test_the_layer_index_is_an_input():
    c = Calibration(focal=50.0, baseline=2.0)
    d = np.full((4, 4), 10.0, np.float32)
    image = np.zeros((4, 4, 3), np.uint8)
    layers = np.arange(16).reshape(4, 4) % 3           # three layers
    points = cloud(c, d, image, layers, np.ones((4, 4), bool))
    np.testing.assert_array_equal(points["layer"], layers.ravel())
    with pytest.raises(ValueError, match=r"^layer: expected indices in \[0, 255\]"):
        cloud(c, d, image, layers + 300, np.ones((4, 4), bool))


@pytest.fixture(scope="module")
def easy_solved(tmp_path_factory, ti_arch):
    from lss_kernels.scenes import make_scene
    folder = tmp_path_factory.mktemp("easy")
    scene = make_scene("easy")
    H, W = scene.left.shape[:2]
    calib = calib_file(folder, width=W, height=H)
    out = folder / "out"
    code = main(["solve", "--preset", "easy", "--calib", str(calib), "--out", str(out),
                 "--arch", ti_arch, "--quiet"])
    assert code == 0
    return out, read_calib(calib)


def test_solve_with_a_calibration_writes_depth_and_clouds(easy_solved):
    out, calib = easy_solved
    for name in ("depth.pfm", "cloud.ply", "object.ply", "confidence.pfm", "confidence.png"):
        assert (out / name).is_file(), name
    d = read_pfm(out / "disparity.pfm")
    z = read_pfm(out / "depth.pfm")
    want = (np.float64(calib.focal) * calib.baseline / (d.astype(np.float64) + calib.doffs))
    np.testing.assert_allclose(z, want.astype(np.float32), rtol=1e-6)
    from lss_kernels.io import read_mask
    fg = read_mask(out / "foreground.png")
    occ = read_mask(out / "occlusion.png")
    every, obj = read_ply(out / "cloud.ply"), read_ply(out / "object.ply")
    assert len(every["xyz"]) == (~occ).sum()           # every pixel seen by both cameras
    assert len(obj["xyz"]) == (fg & ~occ).sum() > 0
    assert set(np.unique(obj["layer"])) == {1}
    assert set(np.unique(every["layer"])) == {0, 1}
    # the object's points, as the pixels' depth, with their confidence
    np.testing.assert_allclose(obj["xyz"][:, 2], z[fg & ~occ], rtol=1e-6)
    np.testing.assert_array_equal(obj["confidence"], read_pfm(out / "confidence.pfm")[fg & ~occ])
    summary = json.loads((out / "summary.json").read_text())
    assert summary["calibration"]["points"] == {"cloud.ply": len(every["xyz"]),
                                                "object.ply": len(obj["xyz"])}


def test_the_result_gives_depth_and_points(ti_arch):
    from lss_kernels import solve
    from lss_kernels.scenes import make_scene
    scene = make_scene("tiny")
    result = solve(scene.left, scene.right, scene.d_max, tuple(scene.init_ellipse))
    c = Calibration(focal=80.0, baseline=0.3, doffs=1.0)
    z = result.depth(c)
    np.testing.assert_allclose(z, (80.0 * 0.3 / (result.disparity.astype(np.float64) + 1.0))
                               .astype(np.float32), rtol=1e-6)
    obj = result.points(c)                          # the object by default
    assert obj.shape == ((result.foreground & ~result.occlusion).sum(), 3)
    every = result.points(c, which="all")
    assert every.shape == ((~result.occlusion).sum(), 3)
    np.testing.assert_allclose(np.sort(obj[:, 2]), np.sort(z[result.foreground]), rtol=1e-6)
    assert result.confidence.shape == result.disparity.shape
    assert (result.confidence[result.occlusion] == 0).all()
    assert 0 <= result.confidence.min() and result.confidence.max() <= 1
    sure = result.points(c, which="all", min_confidence=0.5)
    assert sure.shape == ((~result.occlusion & (result.confidence >= 0.5)).sum(), 3)
    assert 0 < len(sure) < len(every)


def test_solve_with_the_numbers_by_hand(tmp_path, ti_arch):
    out = tmp_path / "out"
    code = main(["solve", "--preset", "tiny", "--focal", "250", "--baseline", "0.12", "--cx",
                 "30.5", "--doffs", "2", "--out", str(out), "--arch", ti_arch, "--quiet"])
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())["calibration"]
    H = read_pfm(out / "depth.pfm").shape[0]
    assert (summary["focal"], summary["baseline"], summary["cx"], summary["cy"],
            summary["doffs"]) == (250.0, 0.12, 30.5, (H - 1) / 2.0, 2.0)
    d, z = read_pfm(out / "disparity.pfm"), read_pfm(out / "depth.pfm")
    np.testing.assert_allclose(z, (250.0 * 0.12 / (d.astype(np.float64) + 2.0))
                               .astype(np.float32), rtol=1e-6)
