"""The bad-input catalogue: every way the API and the CLI can be misused fails with one line
that names the argument, what was expected and what was given (never a Taichi or numpy
traceback); gray, RGBA and 16-bit images are accepted and converted.

API cases go through :func:`lss_kernels.checks.validate.check_inputs` (what ``Solver`` calls
before it allocates anything) or ``Solver`` itself; CLI cases run ``lss solve`` through
:func:`lss_kernels.apps.cli.main` and check exit status 2, one line on stderr and no ``--out``.
"""
import re
import struct
import zlib

import imageio.v3 as iio
import numpy as np
import pytest

from lss_kernels import Params, Solver
from lss_kernels.apps.cli import main
from lss_kernels.io import read_image
from lss_kernels.checks.validate import check_init, check_inputs, parse_init

H, W = 48, 64
P = Params()


def _pair(seed=0, shape=(H, W, 3)):
    rng = np.random.default_rng(seed)
    return rng.random(shape).astype(np.float32), rng.random(shape).astype(np.float32)


def _check(left=None, right=None, d_max=12.0, init=(32.0, 24.0, 10.0, 8.0), frame="left",
           params=P):
    a, b = _pair()
    return check_inputs(a if left is None else left, b if right is None else right, d_max,
                        init, frame, params)


def _write_png16(path, array):
    """A 16-bit PNG written by hand (Pillow cannot write 16-bit RGB)."""
    h, w, c = array.shape
    raw = b"".join(b"\x00" + array[y].astype(">u2").tobytes() for y in range(h))

    def chunk(tag, data):
        return (struct.pack(">I", len(data)) + tag + data
                + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF))

    colour_type = {1: 0, 3: 2, 4: 6}[c]
    path.write_bytes(b"\x89PNG\r\n\x1a\n"
                     + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, colour_type, 0, 0, 0))
                     + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))
    return path


# ------------------------------------------------------------------------------ files
def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"^left: file not found: .*nope\.png$"):
        _check(left=str(tmp_path / "nope.png"))


def test_non_image_file(tmp_path):
    f = tmp_path / "notes.png"
    f.write_text("this is not a picture\n")
    with pytest.raises(ValueError, match=r"^right: could not read as an image: .*notes\.png"):
        _check(right=str(f))


def test_truncated_image_file(tmp_path):
    f = tmp_path / "cut.png"
    iio.imwrite(f, np.zeros((H, W, 3), np.uint8))
    f.write_bytes(f.read_bytes()[:40])
    with pytest.raises(ValueError, match=r"^left: could not read as an image: .*cut\.png"):
        _check(left=str(f))


def test_a_folder_is_not_an_image(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"^left: file not found"):
        _check(left=str(tmp_path))


# ------------------------------------------------------------------------------ images
def test_left_right_size_mismatch():
    a, _ = _pair()
    b, _ = _pair(shape=(H, W - 2, 3))
    with pytest.raises(ValueError, match=r"^right: expected the size of left \(64x48\), "
                                         r"got 62x48$"):
        _check(left=a, right=b)


def test_image_smaller_than_the_largest_patch():
    a, b = _pair(shape=(17, 40, 3))
    with pytest.raises(ValueError, match=r"^left: expected an image at least 18x18 pixels "
                                         r"\(the largest patch\), got 40x17$"):
        _check(left=a, right=b, d_max=8)


def test_image_of_wrong_dimensionality():
    with pytest.raises(ValueError, match=r"^left: expected an image array of shape HxW or "
                                         r"HxWx\{1,3,4\}, got shape \(48, 64, 5\)$"):
        _check(left=np.zeros((H, W, 5), np.float32))


def test_image_of_unsupported_dtype():
    with pytest.raises(ValueError, match=r"^left: expected uint8, uint16, bool or float "
                                         r"pixels, got int64$"):
        _check(left=np.zeros((H, W, 3), np.int64))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nan_or_inf_in_an_image(bad):
    a, _ = _pair()
    a[3, 4, 1] = bad
    with pytest.raises(ValueError, match=r"^left: contains NaN or inf$"):
        _check(left=a)


def test_float_image_out_of_range():
    a, _ = _pair()
    a[0, 0, 0] = 1.5
    with pytest.raises(ValueError, match=r"^right: expected float values in \[0, 1\], "
                                         r"got \[.*, 1\.5\]$"):
        _check(right=a)


@pytest.mark.parametrize("shape", [(H, W), (H, W, 1), (H, W, 4)])
def test_gray_and_rgba_arrays_are_converted(shape):
    rng = np.random.default_rng(1)
    a = (rng.random(shape) * 255).astype(np.uint8)
    left, right, d_max, init = _check(left=a, right=a)
    assert left.shape == (H, W, 3) and left.dtype == np.float32
    pixels = a.reshape(H, W, -1)
    expected = pixels[:, :, :3] if pixels.shape[2] == 4 else np.repeat(pixels, 3, axis=2)
    np.testing.assert_allclose(left, expected / 255.0, atol=1e-6)


def test_gray_rgba_and_16_bit_files_are_converted(tmp_path):
    rng = np.random.default_rng(2)
    g8 = (rng.random((H, W)) * 255).astype(np.uint8)
    rgb16 = (rng.random((H, W, 3)) * 65535).astype(np.uint16)
    g16 = (rng.random((H, W, 1)) * 65535).astype(np.uint16)
    iio.imwrite(tmp_path / "gray.png", g8)
    iio.imwrite(tmp_path / "rgba.png", np.dstack([g8, g8, g8, np.full_like(g8, 7)]))
    _write_png16(tmp_path / "gray16.png", g16)
    _write_png16(tmp_path / "rgb16.png", rgb16)
    for name in ("gray", "rgba", "gray16", "rgb16"):
        img = read_image(str(tmp_path / f"{name}.png"), name)
        assert img.shape == (H, W, 3) and img.dtype == np.float32, name
        assert 0.0 <= img.min() and img.max() <= 1.0, name
    np.testing.assert_allclose(read_image(str(tmp_path / "gray.png"))[:, :, 1], g8 / 255.0,
                               atol=1e-6)
    # 16-bit gray keeps its 16 bits; 16-bit RGB is reduced to 8 bits by the image library
    np.testing.assert_allclose(read_image(str(tmp_path / "gray16.png"))[:, :, 0],
                               g16[:, :, 0] / 65535.0, atol=1e-6)
    np.testing.assert_allclose(read_image(str(tmp_path / "rgb16.png")), rgb16 / 65535.0,
                               atol=1.0 / 255 + 1e-6)
    left, right, _, _ = _check(left=str(tmp_path / "gray16.png"),
                               right=str(tmp_path / "rgba.png"))
    assert left.shape == right.shape == (H, W, 3)


def test_a_grey_view_with_a_colour_one_is_matched_in_grey(ti_arch):
    """One camera grey, the other colour: the colour view is made grey (Rec. 601 luma), so
    that true matches compare like with like; the rendered slanted scene then scores as a
    grey pair does (F1 0.84), where mixed it fell to 0.44."""
    from lss_kernels import metrics, solve
    from lss_kernels.scenes import make_scene
    rng = np.random.default_rng(3)
    grey = (rng.random((H, W)) * 255).astype(np.uint8)
    colour = (rng.random((H, W, 3)) * 255).astype(np.uint8)
    luma = colour.astype(np.float32) / 255 @ np.array([0.299, 0.587, 0.114], np.float32)
    for left, right in ((grey, colour), (colour, grey)):
        got = _check(left=left, right=right)[:2]
        converted = got[1] if left is grey else got[0]
        np.testing.assert_allclose(converted, np.repeat(luma[..., None], 3, axis=2), atol=1e-6)
        kept = got[0] if left is grey else got[1]
        np.testing.assert_allclose(kept[..., 0], grey / 255.0, atol=1e-6)
    # two colour views are left as they are
    np.testing.assert_allclose(_check(left=colour, right=colour)[0], colour / 255.0, atol=1e-6)
    scene = make_scene("slanted")
    grey_left = np.repeat((scene.left @ np.array([0.299, 0.587, 0.114], np.float32))[..., None],
                          3, axis=2)
    r = solve(grey_left, scene.right, scene.d_max, scene.init_ellipse, arch=ti_arch)
    assert metrics.score(r.disparity, r.occlusion, scene)["occ_f1"] > 0.75


# ------------------------------------------------------------------------------ d_max
@pytest.mark.parametrize("d_max", [0, -3.0, W, W + 0.5, 1000])
def test_d_max_out_of_range(d_max):
    with pytest.raises(ValueError, match=r"^d_max: expected 0 < d_max < image width \(64\), "
                                         rf"got {d_max}$"):
        _check(d_max=d_max)


@pytest.mark.parametrize("d_max", [float("nan"), float("inf"), "12", None, True])
def test_d_max_not_a_finite_number(d_max):
    with pytest.raises(ValueError, match=r"^d_max: expected a finite number of pixels, got "):
        _check(d_max=d_max)


def test_d_max_numpy_scalars_are_accepted():
    assert _check(d_max=np.float32(12.5))[2] == 12.5
    assert _check(d_max=np.int64(12))[2] == 12.0


# ------------------------------------------------------------------------------ init
@pytest.mark.parametrize("ellipse", [(200.0, 24.0, 10.0, 8.0), (32.0, -30.0, 10.0, 8.0),
                                     (-12.0, -10.0, 10.0, 8.0)])
def test_init_ellipse_outside_the_image(ellipse):
    with pytest.raises(ValueError, match=r"^init: the ellipse .* (lies outside|covers no "
                                         r"pixel of) the 64x48 image$"):
        _check(init=ellipse)


@pytest.mark.parametrize("rx, ry", [(0.0, 5.0), (5.0, -1.0), (0.99, 5.0), (5.0, 1.4e-110)])
def test_init_ellipse_with_radii_below_a_pixel(rx, ry):
    with pytest.raises(ValueError, match=rf"^init: expected radii of at least 1 pixel, got "
                                         rf"rx={rx:g}, ry={ry:g}$"):
        _check(init=(32.0, 24.0, rx, ry))


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_init_ellipse_with_nan_or_inf(bad):
    with pytest.raises(ValueError, match=r"^init: expected finite numbers, got "):
        _check(init=(32.0, bad, 10.0, 8.0))


def test_init_ellipse_of_three_numbers():
    with pytest.raises(ValueError, match=r"^init: expected an ellipse of 4 numbers "
                                         r"\(cx, cy, rx, ry\), got 3$"):
        _check(init=(32.0, 24.0, 10.0))


@pytest.mark.parametrize("init", [None, "32,24,10,8", object()])
def test_init_of_the_wrong_kind(init):
    with pytest.raises(ValueError, match=r"^init: expected an ellipse \(cx, cy, rx, ry\), a "
                                         r"boolean mask, 'auto', a Point or a Box, got "):
        _check(init=init)


@pytest.mark.parametrize("shape", [(H, W - 1), (W, H), (H, W, 3)])
def test_init_mask_of_the_wrong_shape(shape):
    mask = np.zeros(shape, bool)
    mask[10:20, 10:20] = True
    with pytest.raises(ValueError, match=rf"^init: expected a mask of shape \(48, 64\), got "
                                         rf"shape \({shape[0]}, {shape[1]}"):
        _check(init=mask)


def test_init_mask_empty():
    with pytest.raises(ValueError, match=r"^init: the mask is empty \(no foreground pixel\)$"):
        _check(init=np.zeros((H, W), bool))


def test_init_mask_full():
    with pytest.raises(ValueError, match=r"^init: the mask covers the whole image"):
        _check(init=np.ones((H, W), np.uint8))


def test_init_mask_with_nan():
    mask = np.zeros((H, W), np.float32)
    mask[10:20, 10:20] = 1.0
    mask[0, 0] = np.nan
    with pytest.raises(ValueError, match=r"^init: expected a mask of finite values, got NaN "
                                         r"or inf$"):
        _check(init=mask)


def test_init_mask_as_nested_lists_is_accepted():
    mask = np.zeros((H, W), bool)
    mask[10:20, 10:30] = True
    out = _check(init=mask.astype(int).tolist())[3]
    assert out.dtype == bool and np.array_equal(out, mask)


def test_init_frame_unknown():
    with pytest.raises(ValueError, match=r"^init_frame: expected 'left' or 'cyclopean', "
                                         r"got 'right'$"):
        _check(frame="right")


# ------------------------------------------------------------------------------ --init
@pytest.mark.parametrize("text, message", [
    ("ellipse:1,2,3", r"^--init: expected ellipse:CX,CY,RX,RY with 4 numbers, "
                      r"got 'ellipse:1,2,3'$"),
    ("ellipse:a,b,c,d", r"^--init: expected ellipse:CX,CY,RX,RY with 4 numbers"),
    ("ellipse:1,2,3,4,", r"^--init: expected ellipse:CX,CY,RX,RY with 4 numbers"),
    ("ellipse:nan,2,3,4", r"^--init: expected 4 finite numbers, got 'ellipse:nan,2,3,4'$"),
    ("circle:1,2,3", r"^--init: unknown kind 'circle'; expected auto, point:X,Y, "
                     r"box:X0,Y0,X1,Y1, ellipse:CX,CY,RX,RY or mask:PATH$"),
    ("32,24,10,8", r"^--init: unknown kind '32,24,10,8'"),
    ("", r"^--init: expected auto, point:X,Y, box:X0,Y0,X1,Y1, ellipse:CX,CY,RX,RY or "
         r"mask:PATH, got ''$"),
    ("mask:", r"^--init: expected mask:PATH with a path, got 'mask:'$"),
])
def test_parse_init_malformed(text, message):
    with pytest.raises(ValueError, match=message):
        parse_init(text)


def test_parse_init_missing_mask_file(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"^--init: file not found: .*m\.png$"):
        parse_init(f"mask:{tmp_path / 'm.png'}")


def test_parse_init_reads_ellipses_and_masks(tmp_path):
    assert parse_init("ellipse:32,24.5,10,8") == (32.0, 24.5, 10.0, 8.0)
    m = np.zeros((H, W), np.uint8)
    m[5:9, 6:12] = 255
    iio.imwrite(tmp_path / "m.png", m)
    for spec in (f"mask:{tmp_path / 'm.png'}", str(tmp_path / "m.png")):
        mask = parse_init(spec)
        assert mask.dtype == bool and mask.sum() == 24
        assert np.array_equal(check_init(mask, (H, W)), m > 0)


# ------------------------------------------------------------------------------ Params
@pytest.mark.parametrize("name, value, expected", [
    ("dt", 0.0, r"a number in \(0, 10\]"),
    ("dt", -0.1, r"a number in \(0, 10\]"),
    ("dt", 11.0, r"a number in \(0, 10\]"),
    ("dt", float("nan"), r"a number in \(0, 10\]"),
    ("mu", -1.0, r"a finite number >= 0"),
    ("mu", float("inf"), r"a finite number >= 0"),
    ("alpha", (-0.2, 0.8, 0.1), r"a tuple of three finite numbers >= 0"),
    ("alpha", (0.2, float("nan"), 0.1), r"a tuple of three finite numbers >= 0"),
    ("alpha", (0.2, 0.8), r"a tuple of three finite numbers >= 0"),
    ("beta", -0.4, r"a finite number >= 0"),
    ("max_iterations", 0, r"an integer >= 1"),
    ("max_iterations", 10.5, r"an integer >= 1"),
    ("max_iterations", True, r"an integer >= 1"),
    ("stop_shift", -0.1, r"a finite number of pixels >= 0 \(0: no stopping rule\)"),
    ("stop_shift", float("inf"), r"a finite number of pixels >= 0 \(0: no stopping rule\)"),
    ("stop_surface", -1.0, r"a finite number of pixels >= 0 \(0: no surface test\)"),
    ("stop_patience", 0, r"an integer >= 1"),
    ("narrow_band", -1.0, r"a finite number of pixels >= 0 \(0: no band\)"),
    ("narrow_band", float("inf"), r"a finite number of pixels >= 0 \(0: no band\)"),
    ("background_sweep", -0.05, r"a finite number >= 0"),
    ("background_sweep", float("nan"), r"a finite number >= 0"),
    ("subpixel_messages", 1, r"True or False"),
    ("median_size", 4, r"1, 3, 5 or 7"),
    ("patch_sizes", (3, 8), r"a tuple of increasing integers >= 2, each a multiple of the "
                            r"one before"),
    *(("strip_window", v, r"\(0, 0\) or \(near, far\), integers with 0 <= near, "
                          r"near \+ 2 <= far <= 64")
      for v in ((6, 7), (-1, 20), (6, 80), (6.0, 20), [6, 20])),
])
def test_params_out_of_range(name, value, expected):
    with pytest.raises(ValueError, match=rf"^params\.{name}: expected {expected}, got "):
        Params(**{name: value})


def test_params_unknown_name():
    with pytest.raises(ValueError, match=r"^params: unknown parameter\(s\) \['speed'\]$"):
        Params().replace(speed=2)


def test_solver_refuses_a_non_params(ti_arch):
    a, b = _pair()
    with pytest.raises(TypeError, match=r"^params: expected lss_kernels.Params, got dict$"):
        Solver(a, b, 12, (32, 24, 10, 8), params={"dt": 0.1})


def test_solver_validates_before_allocating(ti_arch):
    a, b = _pair()
    with pytest.raises(ValueError, match=r"^d_max: expected 0 < d_max < image width"):
        Solver(a, b, 64, (32, 24, 10, 8))


def test_fields_bytes_is_a_little_under_what_a_solver_holds(ti_arch):
    from lss_kernels.scenes import make_scene
    from lss_kernels.checks.validate import fields_bytes
    for preset in ("tiny", "easy"):
        scene = make_scene(preset)
        solver = Solver(scene.left, scene.right, scene.d_max, tuple(scene.init_ellipse),
                        params=Params(max_iterations=1))
        held = solver.memory_bytes
        solver.close()
        assert 0.8 * held < fields_bytes(*scene.left.shape[:2], scene.d_max) <= held


def test_a_pair_too_large_for_the_memory_is_refused_before_allocating(ti_arch, monkeypatch):
    from lss_kernels.checks import validate
    a, b = _pair()
    monkeypatch.setattr(validate, "available_memory", lambda: 2**20)
    with pytest.raises(ValueError, match=r"^left: a 64x48 pair searched to d_max 12 needs about "
                                         r"0\.0 GiB for the solver's fields and this machine has "
                                         r"0\.0 GiB available; expected a smaller pair: "
                                         r"downscale both images and d_max by one factor, or "
                                         r"crop them$"):
        Solver(a, b, 12, (32, 24, 10, 8))
    monkeypatch.setattr(validate, "available_memory", lambda: None)   # unknown: no check
    solver = Solver(a, b, 12, (32, 24, 10, 8), params=Params(max_iterations=2))
    assert solver.run().iterations == 2
    # a reset solver allocates nothing: the memory its own fields take is not asked for again
    monkeypatch.setattr(validate, "available_memory", lambda: 2**20)
    solver.reset(a, b, 12, (32, 24, 10, 8))
    assert solver.run().iterations == 2
    solver.close()


def test_unknown_arch(ti_arch):
    a, b = _pair()
    with pytest.raises(ValueError, match=r"^arch: expected one of cpu, cuda, .*, got 'tpu'$"):
        Solver(a, b, 12, (32, 24, 10, 8), arch="tpu")


# ------------------------------------------------------------------------------ CLI
@pytest.fixture
def pair_files(tmp_path):
    a, b = _pair()
    iio.imwrite(tmp_path / "l.png", (a * 255).astype(np.uint8))
    iio.imwrite(tmp_path / "r.png", (b * 255).astype(np.uint8))
    return str(tmp_path / "l.png"), str(tmp_path / "r.png")


def _cli(capsys, tmp_path, args, ti_arch):
    out = tmp_path / "out"
    arch = [] if "--arch" in args else ["--arch", ti_arch]
    code = main(["solve", *args, "--out", str(out), *arch, "--quiet"])
    err = capsys.readouterr().err
    assert code == 2
    assert not out.exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".lss-")] == []
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("lss solve: error: ")
    return lines[0][len("lss solve: error: "):]


@pytest.mark.parametrize("case, message", [
    ("missing_left", r"^left: file not found: .*missing\.png$"),
    ("not_an_image", r"^right: could not read as an image: "),
    ("dmax_zero", r"^d_max: expected 0 < d_max < image width \(64\), got 0"),
    ("dmax_wide", r"^d_max: expected 0 < d_max < image width \(64\), got 64"),
    ("dmax_nan", r"^d_max: expected a finite number of pixels, got nan$"),
    ("init_malformed", r"^--init: expected ellipse:CX,CY,RX,RY with 4 numbers"),
    ("init_unknown", r"^--init: unknown kind 'disc'"),
    ("init_outside", r"^init: the ellipse centred at \(500, 24\) .* lies outside"),
    ("init_radius", r"^init: expected radii of at least 1 pixel, got rx=0, ry=8$"),
    ("init_mask_shape", r"^init: expected a mask of shape \(48, 64\), got shape \(20, 30\)$"),
    ("init_mask_empty", r"^init: the mask is empty"),
    ("no_dmax", r"^--dmax: required with LEFT RIGHT(; this pair's distinct matches reach "
                r"\d+ px, so try --dmax \d+ \(an estimate: .*\))?$"),
    ("init_box_empty", r"^init: expected a box with x0 < x1 and y0 < y1 \(positive area\)"),
    ("init_point_outside", r"^init: expected a point inside the 64x48 image"),
    ("one_image", r"^expected LEFT RIGHT \(two images\) or --scene DIR, got 1 image"),
    ("unknown_arch", r"^arch: expected one of cpu, .*, got 'tpu'$"),
    ("param_dt", r"^params\.dt: expected a number in \(0, 10\], got -1\.0$"),
    ("param_mu_nan", r"^params\.mu: expected a finite number >= 0, got nan$"),
    ("param_unknown", r"^--param: expected NAME=VALUE with a parameter of Params, "
                      r"got 'speed=2'$"),
    ("param_not_a_number", r"^--param beta: expected a float, got 'abc'$"),
    ("param_tuple", r"^--param refine_passes: expected a tuple, written 24:7:8,4:4:2, got "
                    r"'\(\(24,7,8\)\)'$"),
    ("iteration_cap", r"^params\.max_iterations: expected an integer >= 1, got 0$"),
    ("missing_scene", r"^scene: folder not found: "),
])
def test_cli_bad_input(case, message, capsys, tmp_path, pair_files, ti_arch):
    left, right = pair_files
    folder = tmp_path
    good = ["--dmax", "12", "--init", "ellipse:32,24,10,8"]
    if case.startswith("init_mask"):
        m = np.zeros((20, 30) if case == "init_mask_shape" else (H, W), np.uint8)
        if case == "init_mask_shape":
            m[5:10, 5:10] = 255
        iio.imwrite(folder / "mask.png", m)
    (folder / "bad.png").write_text("not an image")
    args = {
        "missing_left": [str(folder / "missing.png"), right, *good],
        "not_an_image": [left, str(folder / "bad.png"), *good],
        "dmax_zero": [left, right, "--dmax", "0", "--init", "ellipse:32,24,10,8"],
        "dmax_wide": [left, right, "--dmax", "64", "--init", "ellipse:32,24,10,8"],
        "dmax_nan": [left, right, "--dmax", "nan", "--init", "ellipse:32,24,10,8"],
        "init_malformed": [left, right, "--dmax", "12", "--init", "ellipse:32,24"],
        "init_unknown": [left, right, "--dmax", "12", "--init", "disc:1,2,3,4"],
        "init_outside": [left, right, "--dmax", "12", "--init", "ellipse:500,24,10,8"],
        "init_radius": [left, right, "--dmax", "12", "--init", "ellipse:32,24,0,8"],
        "init_mask_shape": [left, right, "--dmax", "12", "--init",
                            f"mask:{folder / 'mask.png'}"],
        "init_mask_empty": [left, right, "--dmax", "12", "--init",
                            f"mask:{folder / 'mask.png'}"],
        "no_dmax": [left, right, "--init", "ellipse:32,24,10,8"],
        "init_box_empty": [left, right, "--dmax", "12", "--init", "box:10,10,10,30"],
        "init_point_outside": [left, right, "--dmax", "12", "--init", "point:64.5,3"],
        "one_image": [left, *good],
        "unknown_arch": [left, right, *good, "--arch", "tpu"],
        "param_dt": [left, right, *good, "--param", "dt=-1"],
        "param_mu_nan": [left, right, *good, "--param", "mu=nan"],
        "param_unknown": [left, right, *good, "--param", "speed=2"],
        "param_not_a_number": [left, right, *good, "--param", "beta=abc"],
        "param_tuple": [left, right, *good, "--param", "refine_passes=((24,7,8))"],
        "iteration_cap": [left, right, *good, "--max-iterations", "0"],
        "missing_scene": ["--scene", str(folder / "no_scene")],
    }[case]
    assert re.search(message, _cli(capsys, tmp_path, args, ti_arch))


def test_cli_size_mismatch(capsys, tmp_path, ti_arch):
    a, b = _pair()
    iio.imwrite(tmp_path / "l.png", (a * 255).astype(np.uint8))
    iio.imwrite(tmp_path / "r.png", (b[:, :60] * 255).astype(np.uint8))
    msg = _cli(capsys, tmp_path, [str(tmp_path / "l.png"), str(tmp_path / "r.png"),
                                  "--dmax", "12", "--init", "ellipse:32,24,10,8"], ti_arch)
    assert msg == "right: expected the size of left (64x48), got 60x48"


def test_cli_failure_keeps_an_existing_out_untouched(capsys, tmp_path, pair_files, ti_arch):
    out = tmp_path / "out"
    out.mkdir()
    (out / "previous.txt").write_text("kept")
    left, right = pair_files
    code = main(["solve", left, right, "--dmax", "0", "--init", "ellipse:32,24,10,8",
                 "--out", str(out), "--arch", ti_arch, "--quiet"])
    assert code == 2
    assert "d_max" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["previous.txt"]


def test_cli_pair_too_large_for_the_memory(capsys, tmp_path, pair_files, ti_arch, monkeypatch):
    from lss_kernels.checks import validate
    monkeypatch.setattr(validate, "available_memory", lambda: 2**20)
    left, right = pair_files
    message = _cli(capsys, tmp_path, [left, right, "--dmax", "12", "--init",
                                      "ellipse:32,24,10,8"], ti_arch)
    assert re.match(r"^left: a 64x48 pair searched to d_max 12 needs about .* GiB available; "
                    r"expected a smaller pair", message)


# ------------------------------------------------------------------------------ calibration
def _calib(focal0=100.0, focal1=100.0, cy1=24.0, doffs=4.0, baseline=0.1, size=(64, 48),
           drop=(), extra=""):
    lines = {"cam0": f"[{focal0} 0 30; 0 {focal0} 24; 0 0 1]",
             "cam1": f"[{focal1} 0 34; 0 {focal1} {cy1}; 0 0 1]",
             "doffs": doffs, "baseline": baseline, "width": size[0], "height": size[1]}
    return "".join(f"{k}={v}\n" for k, v in lines.items() if k not in drop) + extra


@pytest.mark.parametrize("case, message", [
    ("file_missing", r"^calib: file not found: .*nope\.txt$"),
    ("focal_differs", r"^calib .*calib\.txt: expected cam0 and cam1 of one focal length \(a "
                      r"rectified pair\), got 100 and 120$"),
    ("row_differs", r"^calib .*: expected cam0 and cam1 of one principal row cy \(a rectified "
                    r"pair\), got 24 and 30$"),
    ("size", r"^--calib: expected a calibration of the 64x48 images, got one of 128x96 "
             r"\(rescale"),
    ("missing_key", r"^calib .*: missing baseline; expected cam0, cam1, doffs, baseline$"),
    ("doffs", r"^calib .*: doffs: expected cx1 - cx0 = 4, got 9$"),
    ("baseline_zero", r"^calib .*: baseline: expected a number > 0, got 0$"),
    ("not_a_number", r"^calib .*: baseline: expected a number, got 'ten'$"),
    ("unknown_key", r"^calib .*: unknown key 'focal'; expected cam0, cam1, doffs"),
    ("not_key_value", r"^calib .*: line 7: expected key=value, got 'hello'$"),
    ("matrix", r"^calib .*: cam0: expected a 3x3 matrix \[f 0 cx; 0 f cy; 0 0 1\], got "),
    ("focal_negative", r"^--focal: expected a finite number > 0, got -5\.0$"),
    ("baseline_nan", r"^--baseline: expected a finite number > 0, got nan$"),
    ("baseline_missing", r"^--baseline: required with --focal$"),
    ("focal_missing", r"^--focal: required with --baseline, --cx$"),
    ("both", r"^--calib: expected a calibration file or --focal and --baseline, got both "
             r"\(--focal\)$"),
])
def test_cli_bad_calibration(case, message, capsys, tmp_path, pair_files, ti_arch):
    left, right = pair_files
    file = tmp_path / "calib.txt"
    text = {"focal_differs": _calib(focal1=120.0), "row_differs": _calib(cy1=30.0),
            "size": _calib(size=(128, 96)), "missing_key": _calib(drop=("baseline",)),
            "doffs": _calib(doffs=9.0), "baseline_zero": _calib(baseline=0),
            "not_a_number": _calib(baseline="ten"), "unknown_key": _calib(extra="focal=3\n"),
            "not_key_value": _calib(extra="hello\n"),
            "matrix": _calib().replace("[100.0 0 30; 0 100.0 24; 0 0 1]", "[100 0 30]")}
    file.write_text(text.get(case, _calib()))
    calib = {"file_missing": ["--calib", str(tmp_path / "nope.txt")],
             "focal_negative": ["--focal", "-5", "--baseline", "1"],
             "baseline_nan": ["--focal", "5", "--baseline", "nan"],
             "baseline_missing": ["--focal", "5"],
             "focal_missing": ["--baseline", "5", "--cx", "3"],
             "both": ["--calib", str(file), "--focal", "5"]}.get(case, ["--calib", str(file)])
    args = [left, right, "--dmax", "12", "--init", "ellipse:32,24,10,8", *calib]
    assert re.search(message, _cli(capsys, tmp_path, args, ti_arch))
