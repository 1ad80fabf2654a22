"""Tests of lss_kernels.apps.demo: argument parsing (no Taichi) and one end-to-end run of
``lss demo`` on the tiny built-in scene (frames, a decodable looping GIF, patch.png)."""
import argparse
import os

import imageio.v3 as iio
import numpy as np
import pytest

from lss_kernels.apps import demo


def _parser():
    parser = argparse.ArgumentParser(prog="lss")
    demo.add_cli(parser.add_subparsers(dest="command"))
    return parser


def test_parse_init_ellipse_and_mask(tmp_path):
    assert demo.parse_init("ellipse:10,20.5,3,4") == (10.0, 20.5, 3.0, 4.0)
    mask = np.zeros((6, 8), np.uint8)
    mask[2:4, 3:6] = 255
    path = tmp_path / "m.png"
    iio.imwrite(path, mask)
    m = demo.parse_init(str(path), (6, 8))
    assert m.dtype == bool and m.sum() == 6 and m[2, 3]


@pytest.mark.parametrize("spec, match", [
    ("ellipse:1,2,3", "4 numbers"),
    ("ellipse:a,b,c,d", "4 numbers"),
    ("ellipse:1,2,0,3", "radii"),
    ("circle:1,2,3", "ellipse:CX,CY,RX,RY"),
    ("box:1,2,1,5", "positive area"),
    ("point:100,2", "point inside"),
])
def test_parse_init_errors(spec, match):
    with pytest.raises(ValueError, match=match):
        demo.parse_init(spec, (48, 64))


def test_parse_init_mask_of_wrong_size(tmp_path):
    path = tmp_path / "m.png"
    iio.imwrite(path, np.full((5, 5), 255, np.uint8))
    with pytest.raises(ValueError, match=r"shape \(6, 8\), got shape \(5, 5\)"):
        demo.parse_init(str(path), (6, 8))


def test_parse_patch():
    assert demo.parse_patch("3,4,1", 3) == (3, 4, 1)
    with pytest.raises(ValueError, match="three integers"):
        demo.parse_patch("3,4")
    with pytest.raises(ValueError, match="LEVEL"):
        demo.parse_patch("3,4,3", 3)


def test_recorded_iterations_and_default_patch():
    assert demo.recorded_iterations(20, 5) == [5, 10, 15, 20]
    assert demo.recorded_iterations(17, 5) == [5, 10, 15, 17]
    assert demo.recorded_iterations(3, 5) == [3]
    phi = -np.ones((20, 30))
    phi[5:12, 8:20] = 1.0
    assert demo.default_patch(phi, 3) == (8, 8, 1)
    assert demo.default_patch(phi, 3, (3, 9, 18)) == (12, 8, 1)


@pytest.mark.parametrize("argv, match", [
    (["demo", "l.png", "r.png", "--dmax", "16", "--init", "ellipse:1,2"], "--init"),
    (["demo", "l.png"], "two images"),
    (["demo", "--patch", "1,2"], "--patch"),
    (["demo", "--every", "0"], "--every"),
])
def test_cli_argument_errors_exit_2(tmp_path, capsys, argv, match):
    for name in ("l.png", "r.png"):
        iio.imwrite(tmp_path / name, np.zeros((8, 8, 3), np.uint8))
    argv = [os.path.join(tmp_path, a) if a.endswith(".png") else a for a in argv]
    args = _parser().parse_args(argv)
    assert args.func(args) == 2
    err = capsys.readouterr().err.strip()
    assert match in err and len(err.splitlines()) == 1


@pytest.mark.slow
def test_lss_demo_with_no_arguments(tmp_path):
    """``lss demo`` exactly as a new user types it, in a fresh process: the default arch
    (``auto``) runs on the CPU where there is no GPU (CI's machine), with one line saying so,
    and the default output folder gets the frames, the GIF and the pictures."""
    import subprocess
    import sys
    from lss_kernels.kernels import backend
    proc = subprocess.run([sys.executable, "-m", "lss_kernels.apps.cli", "demo"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    if not backend.probe("cuda")[0]:
        assert "running on the CPU" in proc.stderr
        assert "arch cpu" in proc.stdout
    out = tmp_path / "lss_demo"
    assert "iterations" in proc.stdout.strip().splitlines()[-1]
    frames = sorted((out / "frames").glob("frame_*.png"))
    assert len(frames) >= 2
    first = iio.imread(frames[0])
    gif = iio.imread(out / "evolution.gif", index=None)
    assert gif.shape[0] == len(frames) and gif.shape[1:3] == first.shape[:2]
    assert iio.imread(out / "patch.png").ndim == 3


def test_demo_end_to_end_on_tiny_scene(ti_arch, tmp_path, capsys):
    pytest.importorskip("lss_kernels.scenes")
    out = tmp_path / "demo"
    args = _parser().parse_args(["demo", "--preset", "tiny", "--iterations", "20", "--every",
                                 "5", "--arch", ti_arch, "--out", str(out)])
    assert args.func(args) == 0
    stdout = capsys.readouterr().out
    assert "iter    20" in stdout

    n = len(demo.recorded_iterations(20, 5))
    frames = sorted((out / "frames").glob("frame_*.png"))
    assert [f.name for f in frames] == [f"frame_{i:04d}.png" for i in range(n)]
    first = iio.imread(frames[0])
    gif = iio.imread(out / "evolution.gif", index=None)
    assert gif.shape[0] == n and gif.shape[1:3] == first.shape[:2]
    assert iio.immeta(out / "evolution.gif").get("loop") == 0

    from lss_kernels import scenes
    scene = scenes.make_scene("tiny")
    h, w = scene.left.shape[:2]
    assert first.shape[1] == 5 * 240                # five panels: ground truth exists
    assert iio.imread(out / "patch.png").ndim == 3
    assert iio.imread(out / "disparity.png").shape[:2] == (h, w)
    assert iio.imread(out / "overlay.png").shape[:2] == (h, w)
    # the layer map over the left image: the object tinted red, the rest grey
    layers = iio.imread(out / "layers.png").astype(int)
    assert layers.shape[:2] == (h, w)
    redder = (layers[..., 0] - layers[..., 2]) > 40
    assert redder[scene.fg_left].mean() > 0.8 and redder[~scene.fg_left].mean() < 0.2
