"""Images, PFM, masks and scene folders: formats, round trips and one-line errors."""
import json

import imageio.v3 as iio
import numpy as np
import pytest

from lss_kernels.io import (Scene, list_scenes, load_scene, read_image, read_mask, read_pfm,
                            save_scene, write_mask, write_pfm, write_png)



# ---------------------------------------------------------------------------------------------
# read_image
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("shape", [(4, 5), (4, 5, 1), (4, 5, 3), (4, 5, 4)])
@pytest.mark.parametrize("dtype, top", [(np.uint8, 255), (np.uint16, 65535)])
def test_read_image_files(tmp_path, shape, dtype, top):
    rng = np.random.default_rng(0)
    a = rng.integers(0, top + 1, shape, dtype=np.int64).astype(dtype)
    if len(shape) == 3 and shape[2] == 4:
        a[..., 3] = top // 2                     # alpha must be dropped, not blended
    # Pillow writes 16-bit PNG in gray only; 16-bit colour goes through TIFF.
    path = tmp_path / ("img.tif" if dtype == np.uint16 and len(shape) == 3 and shape[2] > 1
                       else "img.png")
    iio.imwrite(path, a[..., 0] if shape == (4, 5, 1) else a)
    img = read_image(path, "left")
    assert img.dtype == np.float32 and img.shape == (4, 5, 3)
    a = a.reshape(4, 5, -1)
    rgb = np.repeat(a, 3, 2) if a.shape[2] == 1 else a[..., :3]
    np.testing.assert_allclose(img, rgb / top, atol=1e-7)


def test_read_image_arrays():
    f = np.linspace(0, 1, 12, dtype=np.float64).reshape(2, 2, 3)
    np.testing.assert_array_equal(read_image(f), f.astype(np.float32))
    assert read_image(np.full((2, 3), 255, np.uint8)).tolist() == np.ones((2, 3, 3)).tolist()
    assert read_image(np.ones((2, 3), bool)).shape == (2, 3, 3)
    assert read_image(np.zeros((1, 1, 1))).shape == (1, 1, 3)


@pytest.mark.parametrize("src, message", [
    (np.zeros(3), "right: expected an image array of shape HxW or HxWx{1,3,4}, got shape (3,)"),
    (np.zeros((2, 2, 2)), "right: expected an image array of shape HxW or HxWx{1,3,4}, got shape (2, 2, 2)"),
    (np.full((2, 2), np.nan), "right: contains NaN or inf"),
    (np.full((2, 2), 1.5), "right: expected float values in [0, 1], got [1.5, 1.5]"),
    (np.zeros((2, 2), np.int64), "right: expected uint8, uint16, bool or float pixels, got int64"),
])
def test_read_image_array_errors(src, message):
    with pytest.raises(ValueError) as err:
        read_image(src, "right")
    assert str(err.value) == message


def test_read_image_file_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"^left: file not found: .*missing\.png$"):
        read_image(tmp_path / "missing.png", "left")
    bad = tmp_path / "bad.png"
    bad.write_text("not an image")
    with pytest.raises(ValueError, match=r"^left: could not read as an image: .*bad\.png") as err:
        read_image(bad, "left")
    assert "\n" not in str(err.value) and err.value.__cause__ is not None


# ---------------------------------------------------------------------------------------------
# Masks and PNG
# ---------------------------------------------------------------------------------------------

def test_masks(tmp_path):
    m = np.array([[True, False, True], [False, False, True]])
    write_mask(tmp_path / "m.png", m)
    raw = iio.imread(tmp_path / "m.png")
    assert raw.dtype == np.uint8 and raw.ndim == 2 and set(np.unique(raw)) == {0, 255}
    np.testing.assert_array_equal(read_mask(tmp_path / "m.png"), m)
    rgb = np.zeros((2, 3, 3), np.uint8)
    rgb[0, 1, 2] = 7                             # any nonzero channel is True
    iio.imwrite(tmp_path / "rgb.png", rgb)
    assert read_mask(tmp_path / "rgb.png").tolist() == [[False, True, False], [False] * 3]
    with pytest.raises(FileNotFoundError, match="^occ: file not found"):
        read_mask(tmp_path / "none.png", "occ")
    with pytest.raises(ValueError, match="expected a mask of shape HxW"):
        write_mask(tmp_path / "x.png", np.zeros((2, 2, 3)))
    with pytest.raises(ValueError, match="expected a uint8 array"):
        write_png(tmp_path / "x.png", np.zeros((2, 2)))


# ---------------------------------------------------------------------------------------------
# PFM
# ---------------------------------------------------------------------------------------------

def test_pfm_round_trip_and_layout(tmp_path):
    a = np.array([[1.5, np.inf, -2.0], [0.0, 3.25, np.nan]], np.float32)
    path = write_pfm(tmp_path / "d.pfm", a)
    data = path.read_bytes()
    header = b"Pf\n3 2\n-1.0\n"
    assert data.startswith(header)
    # Middlebury layout: little-endian, bottom row first.
    np.testing.assert_array_equal(np.frombuffer(data[len(header):], "<f4"),
                                  np.concatenate([a[1], a[0]]))
    b = read_pfm(path)
    assert b.dtype == np.float32 and b.shape == (2, 3)
    np.testing.assert_array_equal(b, a)          # inf and NaN included


def test_pfm_big_endian_and_errors(tmp_path):
    a = np.arange(6, dtype=np.float32).reshape(2, 3)
    (tmp_path / "be.pfm").write_bytes(b"Pf\n3 2\n1.0\n" + np.flipud(a).astype(">f4").tobytes())
    np.testing.assert_array_equal(read_pfm(tmp_path / "be.pfm"), a)
    cases = {"junk.pfm": b"P5\n3 2\n255\n" + bytes(6),
             "short.pfm": b"Pf\n3 2\n-1.0\n" + bytes(20),
             "colour.pfm": b"PF\n3 2\n-1.0\n" + bytes(72),
             "zero.pfm": b"Pf\n3 2\n0\n" + bytes(24)}
    messages = {"junk.pfm": "malformed header", "short.pfm": "should hold 3x2 float32",
                "colour.pfm": "expected a grayscale 'Pf'", "zero.pfm": "malformed header"}
    for name, data in cases.items():
        (tmp_path / name).write_bytes(data)
        with pytest.raises(ValueError, match=messages[name]):
            read_pfm(tmp_path / name)
    with pytest.raises(FileNotFoundError):
        read_pfm(tmp_path / "none.pfm")
    with pytest.raises(ValueError, match="expected a non-empty array of shape HxW"):
        write_pfm(tmp_path / "x.pfm", np.zeros(3))


# ---------------------------------------------------------------------------------------------
# Scene folders
# ---------------------------------------------------------------------------------------------

def _scene(with_truth=True):
    rng = np.random.default_rng(3)
    h, w = 6, 9
    img = lambda: np.round(rng.random((h, w, 3)) * 255).astype(np.float32) / 255  # noqa: E731
    mask = lambda: rng.random((h, w)) < 0.3                                      # noqa: E731
    truth = {}
    if with_truth:
        disp = rng.random((h, w)).astype(np.float32) * 10
        disp[0, 0] = np.inf
        truth = dict(disp_left=disp, fg_left=mask(), occ_left=mask(), roi_fg=mask(),
                     roi_bg=mask(), boundary=mask())
    return Scene(name="toy", left=img(), right=img(), d_max=12.0,
                 init_ellipse=(4.0, 3.0, 2.0, 1.5), init_ellipse_cyclopean=(2.0, 3.0, 2.0, 1.5),
                 meta={"note": "x"}, **truth)


def test_scene_round_trip(tmp_path):
    scene = _scene()
    save_scene(tmp_path / "a" / "toy", scene)
    back = load_scene(tmp_path / "a" / "toy")
    for key in ("left", "right", "disp_left", "fg_left", "occ_left", "roi_fg", "roi_bg",
                "boundary"):
        np.testing.assert_array_equal(getattr(back, key), getattr(scene, key), err_msg=key)
    assert back.left.dtype == np.float32 and back.fg_left.dtype == bool
    assert (back.name, back.d_max, back.init_ellipse, back.init_ellipse_cyclopean) == (
        "toy", 12.0, (4.0, 3.0, 2.0, 1.5), (2.0, 3.0, 2.0, 1.5))
    assert back.meta["note"] == "x" and back.meta["width"] == 9 and back.meta["height"] == 6
    assert back.path == str(tmp_path / "a" / "toy")


def test_scene_optional_files_absent(tmp_path):
    scene = _scene(with_truth=False)
    scene.init_ellipse_cyclopean = None
    save_scene(tmp_path / "s", scene)
    assert sorted(p.name for p in (tmp_path / "s").iterdir()) == ["left.png", "meta.json",
                                                                 "right.png"]
    back = load_scene(tmp_path / "s")
    assert back.disp_left is None and back.boundary is None and back.fg_left is None
    assert back.init_ellipse_cyclopean is None


def test_scene_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="scene: folder not found"):
        load_scene(tmp_path / "nowhere")
    folder = tmp_path / "s"
    save_scene(folder, _scene())
    (folder / "right.png").unlink()
    with pytest.raises(FileNotFoundError, match=r"scene .*s: right\.png: file not found"):
        load_scene(folder)
    save_scene(folder, _scene())
    iio.imwrite(folder / "fg_left.png", np.zeros((5, 9), np.uint8))
    with pytest.raises(ValueError, match=r"fg_left\.png has size \(5, 9\), left\.png \(6, 9\)"):
        load_scene(folder)
    meta = json.loads((folder / "meta.json").read_text())
    del meta["d_max"]
    (folder / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match="meta.json has no 'd_max'"):
        load_scene(folder)
    (folder / "meta.json").unlink()
    with pytest.raises(FileNotFoundError, match=r"scene .*s: missing meta\.json"):
        load_scene(folder)


def test_list_scenes(tmp_path):
    with pytest.raises(FileNotFoundError):
        list_scenes(tmp_path / "none")
    with pytest.raises(ValueError, match="no scene folders"):
        list_scenes(tmp_path)
    for name in ("b", "a"):
        save_scene(tmp_path / name, _scene(with_truth=False))
    (tmp_path / "not_a_scene").mkdir()
    assert [p.name for p in list_scenes(tmp_path)] == ["a", "b"]


def test_load_real_scene(paper15):
    scene = load_scene(paper15 / "scene03_flowerpots")
    assert scene.name == "scene03_flowerpots"
    assert scene.left.shape == scene.right.shape == (155, 400, 3)
    assert scene.disp_left.shape == (155, 400) and scene.disp_left.dtype == np.float32
    assert scene.d_max == 112.0 and scene.init_ellipse == (237.8, 99.0, 70.0, 70.0)
    assert scene.init_ellipse_cyclopean == (199.0, 99.0, 70.0, 70.0)
    for key in ("fg_left", "occ_left", "roi_fg", "roi_bg", "boundary"):
        assert getattr(scene, key).dtype == bool and getattr(scene, key).any()
    finite = scene.disp_left[np.isfinite(scene.disp_left)]
    assert 0 <= finite.min() and finite.max() < scene.d_max
    # The foreground is nearer: its known disparities exceed the background's on average.
    fg = scene.fg_left & np.isfinite(scene.disp_left)
    bg = ~scene.fg_left & np.isfinite(scene.disp_left)
    assert scene.disp_left[fg].mean() > scene.disp_left[bg].mean()
