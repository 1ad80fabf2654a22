"""Images, PFM disparities, masks and scene folders.

Conventions (``docs/scene-format.md``): the left image is the reference, ``x_right = x_left - d`` with
``d >= 0``.  Images are float32 ``(H, W, 3)`` arrays in ``[0, 1]``; masks are bool ``(H, W)``;
disparities are float32 ``(H, W)`` in left-view pixels with ``inf`` = unknown, stored as PFM in
the Middlebury layout (``Pf`` grayscale header, scale ``-1.0`` = little-endian, rows bottom-up).

A scene folder holds ``left.png``, ``right.png`` and ``meta.json`` (required) and optionally
``disp_left.pfm``, ``fg_left.png``, ``occ_left.png``, ``roi_fg.png``, ``roi_bg.png``,
``boundary.png`` and ``layers_left.png``; :func:`load_scene` and :func:`save_scene` read and
write it.

Every reader fails with a one-line ``ValueError`` or ``FileNotFoundError`` that names the
argument, what was expected and what was given; errors of the image library are chained, never
shown raw.
"""
from __future__ import annotations

import json
import os
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import imageio.v3 as iio
import numpy as np

__all__ = ["Scene", "list_scenes", "load_scene", "read_image", "read_mask", "read_pfm",
           "save_scene", "write_mask", "write_pfm", "write_png"]

#: Optional mask files of a scene folder, by :class:`Scene` field name.
_MASK_FILES = ("fg_left", "occ_left", "roi_fg", "roi_bg", "boundary")
_PFM_HEADER = re.compile(rb"^(P[Ff])\s+(\d+)\s+(\d+)\s+([-+0-9.eE]+)\s")


# ---------------------------------------------------------------------------------------------
# Images and masks
# ---------------------------------------------------------------------------------------------

def _imread(path, name: str) -> np.ndarray:
    """Pixels of an image file, with one-line errors naming ``name``."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{name}: file not found: {path}")
    try:
        with warnings.catch_warnings():
            # imageio probes its plugins in turn and some warn of their own deprecation
            # (or leave a file open) on a file none can read: nothing a user can act on
            warnings.simplefilter("ignore", DeprecationWarning)
            warnings.simplefilter("ignore", ResourceWarning)
            return np.asarray(iio.imread(path))
    except Exception as exc:  # imageio raises many types; all mean "not an image"
        detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ValueError(f"{name}: could not read as an image: {path} ({detail})") from exc


def _as_pixels(src, name: str) -> np.ndarray:
    """The array behind ``src`` (a path or an array), shape-checked: ``(H, W, C)``, C in 1, 3, 4."""
    a = _imread(src, name) if isinstance(src, (str, os.PathLike)) else np.asarray(src)
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3 or a.shape[2] not in (1, 3, 4) or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"{name}: expected an image array of shape HxW or HxWx{{1,3,4}}, "
                         f"got shape {a.shape}")
    return a


def read_image(src, name: str = "image") -> np.ndarray:
    """Read an image as float32 RGB in ``[0, 1]``.

    Parameters
    ----------
    src : str, path-like or ndarray
        An image file (8- or 16-bit; gray, RGB or RGBA) or an array of shape ``(H, W)``,
        ``(H, W, 1)``, ``(H, W, 3)`` or ``(H, W, 4)``: ``uint8`` (divided by 255), ``uint16``
        (divided by 65535), ``bool``, or float with finite values in ``[0, 1]``.
    name : str
        What the image is (``"left"``, ``"right"``), used in error messages.

    Returns
    -------
    ndarray, float32, shape (H, W, 3)
        Gray is replicated to three channels; alpha is dropped.

    Raises
    ------
    FileNotFoundError
        ``src`` is a path to no file.
    ValueError
        The file is not an image, or the array has the wrong shape, type or values.
    """
    a = _as_pixels(src, name)
    if a.dtype == np.uint8:
        img = a.astype(np.float32) / 255.0
    elif a.dtype == np.uint16:
        img = a.astype(np.float32) / 65535.0
    elif a.dtype == bool:
        img = a.astype(np.float32)
    elif np.issubdtype(a.dtype, np.floating):
        img = a.astype(np.float32)
        if not np.isfinite(img).all():
            raise ValueError(f"{name}: contains NaN or inf")
        if img.min() < 0.0 or img.max() > 1.0:
            raise ValueError(f"{name}: expected float values in [0, 1], "
                             f"got [{img.min():g}, {img.max():g}]")
    else:
        raise ValueError(f"{name}: expected uint8, uint16, bool or float pixels, got {a.dtype}")
    img = img[:, :, :3]
    return np.ascontiguousarray(np.repeat(img, 3, axis=2) if img.shape[2] == 1 else img)


def read_mask(src, name: str = "mask") -> np.ndarray:
    """Read a binary mask: any nonzero channel of a pixel means True.

    Parameters
    ----------
    src : str, path-like or ndarray
        An 8-bit gray or RGB(A) image file, or an array of shape ``(H, W)`` or ``(H, W, C)``.
    name : str
        What the mask is, used in error messages.

    Returns
    -------
    ndarray, bool, shape (H, W)
    """
    a = _as_pixels(src, name)
    return np.ascontiguousarray((a[:, :, :3] != 0).any(axis=2))


def write_png(path, array) -> Path:
    """Write an 8-bit PNG.

    Parameters
    ----------
    path : str or path-like
        Target file (its folder must exist).
    array : ndarray, uint8, shape (H, W), (H, W, 3) or (H, W, 4)

    Returns
    -------
    Path
        ``path``.
    """
    a = np.asarray(array)
    if a.dtype != np.uint8 or not (a.ndim == 2 or (a.ndim == 3 and a.shape[2] in (3, 4))):
        raise ValueError(f"write_png: expected a uint8 array of shape HxW or HxWx{{3,4}}, "
                         f"got {a.dtype} of shape {a.shape}")
    iio.imwrite(Path(path), a, extension=".png")
    return Path(path)


def write_mask(path, mask) -> Path:
    """Write a bool ``(H, W)`` mask as an 8-bit gray PNG, 255 = True; returns ``path``."""
    m = np.asarray(mask)
    if m.ndim != 2:
        raise ValueError(f"write_mask: expected a mask of shape HxW, got shape {m.shape}")
    return write_png(path, np.where(m != 0, 255, 0).astype(np.uint8))


def _to_uint8(image: np.ndarray) -> np.ndarray:
    """float ``[0, 1]`` image to uint8, rounding to the nearest level."""
    return np.round(np.clip(image, 0.0, 1.0) * 255.0).astype(np.uint8)


# ---------------------------------------------------------------------------------------------
# PFM
# ---------------------------------------------------------------------------------------------

def read_pfm(path) -> np.ndarray:
    """Read a grayscale PFM disparity map.

    Parameters
    ----------
    path : str or path-like
        A ``Pf`` file; a negative scale means little-endian, a positive one big-endian; rows are
        stored bottom-up.

    Returns
    -------
    ndarray, float32, shape (H, W)
        Top row first; ``inf`` (unknown) and NaN are kept as stored.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"pfm: file not found: {path}")
    data = path.read_bytes()
    m = _PFM_HEADER.match(data)
    if m is None:
        raise ValueError(f"pfm: malformed header in {path}: expected 'Pf', width, height and "
                         f"scale, got {data[:32]!r}")
    magic, w, h = m.group(1), int(m.group(2)), int(m.group(3))
    if magic != b"Pf":
        raise ValueError(f"pfm: expected a grayscale 'Pf' file, got a colour 'PF' file: {path}")
    try:
        scale = float(m.group(4))
    except ValueError as exc:
        raise ValueError(f"pfm: malformed scale {m.group(4)!r} in {path}") from exc
    if scale == 0.0 or w == 0 or h == 0:
        raise ValueError(f"pfm: malformed header in {path}: width {w}, height {h}, scale {scale}")
    body = data[m.end():]
    if len(body) != 4 * w * h:
        raise ValueError(f"pfm: {path} should hold {w}x{h} float32 values ({4 * w * h} bytes) "
                         f"after its header, holds {len(body)} bytes")
    dtype = "<f4" if scale < 0 else ">f4"
    return np.flipud(np.frombuffer(body, dtype=dtype).reshape(h, w)).astype(np.float32)


def write_pfm(path, array) -> Path:
    """Write a float32 ``(H, W)`` array (top row first) as a Middlebury PFM; returns ``path``.

    The header is ``Pf``, ``W H`` and scale ``-1.0`` (little-endian); rows are stored bottom-up.
    Values, ``inf`` and NaN included, round-trip exactly through :func:`read_pfm`.
    """
    a = np.asarray(array)
    if a.ndim != 2 or a.size == 0:
        raise ValueError(f"write_pfm: expected a non-empty array of shape HxW, got shape {a.shape}")
    h, w = a.shape
    Path(path).write_bytes(f"Pf\n{w} {h}\n-1.0\n".encode("ascii")
                           + np.flipud(a).astype("<f4").tobytes())
    return Path(path)


# ---------------------------------------------------------------------------------------------
# Scene folders
# ---------------------------------------------------------------------------------------------

@dataclass
class Scene:
    """A rectified stereo pair with its ground truth (``docs/scene-format.md``).

    Attributes
    ----------
    name : str
        Scene name (the folder name unless ``meta.json`` gives one).
    left, right : ndarray, float32, shape (H, W, 3)
        Rectified pair in ``[0, 1]``; the left image is the reference.
    d_max : float
        Largest disparity to search, in left-view pixels.
    init_ellipse : tuple of float or None
        ``(cx, cy, rx, ry)``: the initial boundary in left-view pixel coordinates (0-based,
        x to the right, y down); None: the solvers find one (``init="auto"``).
    init_ellipse_cyclopean : tuple of float or None
        The same ellipse in the cyclopean frame, when known.
    init_point : tuple of float or None
        ``(x, y)``: a click on the object (left view), the start when there is no ellipse.
    disp_left : ndarray, float32, shape (H, W), or None
        Ground-truth left-view disparity; ``inf`` = unknown.
    fg_left, occ_left, roi_fg, roi_bg, boundary : ndarray, bool, shape (H, W), or None
        Left-view foreground, occlusion (seen by the left camera only), the foreground and
        background parts of the evaluation band, and the true boundary pixels.
    layers_left : ndarray, uint8, shape (H, W), or None
        The index of the surface each left pixel sees (0: the background).
    meta : dict
        Everything in ``meta.json``.
    path : str or None
        The folder the scene was read from.
    """

    name: str
    left: np.ndarray
    right: np.ndarray
    d_max: float
    init_ellipse: tuple | None
    init_ellipse_cyclopean: tuple | None = None
    disp_left: np.ndarray | None = None
    fg_left: np.ndarray | None = None
    occ_left: np.ndarray | None = None
    roi_fg: np.ndarray | None = None
    roi_bg: np.ndarray | None = None
    boundary: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    path: str | None = None
    init_point: tuple | None = None
    layers_left: np.ndarray | None = None


def _ellipse(value, what: str) -> tuple:
    """``[cx, cy, rx, ry]`` from meta.json as a tuple of four floats."""
    try:
        e = tuple(float(v) for v in value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{what}: expected [cx, cy, rx, ry], got {value!r}") from exc
    if len(e) != 4 or not all(np.isfinite(e)) or e[2] <= 0 or e[3] <= 0:
        raise ValueError(f"{what}: expected [cx, cy, rx, ry] with rx, ry > 0, got {value!r}")
    return e


def _point(value, what: str) -> tuple:
    """``[x, y]`` from meta.json as a tuple of two finite floats."""
    try:
        p = tuple(float(v) for v in value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{what}: expected [x, y], got {value!r}") from exc
    if len(p) != 2 or not all(np.isfinite(p)):
        raise ValueError(f"{what}: expected [x, y] of two finite numbers, got {value!r}")
    return p


def _read_layers(path, name: str) -> np.ndarray:
    """An 8-bit gray index map (``layers_left.png``) as uint8 ``(H, W)``."""
    a = _as_pixels(path, name)
    if a.dtype != np.uint8 or a.shape[2] != 1:
        raise ValueError(f"{name}: expected an 8-bit gray image of layer indices, got "
                         f"{a.dtype} with {a.shape[2]} channel(s)")
    return np.ascontiguousarray(a[:, :, 0])


def _read_meta(folder: Path) -> dict:
    file = folder / "meta.json"
    if not file.is_file():
        raise FileNotFoundError(f"scene {folder}: missing meta.json")
    try:
        meta = json.loads(file.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise ValueError(f"scene {folder}: meta.json is not valid JSON ({exc})") from exc
    if not isinstance(meta, dict):
        raise ValueError(f"scene {folder}: meta.json should hold an object, got {type(meta).__name__}")
    if "d_max" not in meta:
        raise ValueError(f"scene {folder}: meta.json has no 'd_max'")
    return meta


def load_scene(folder) -> Scene:
    """Read a scene folder (``docs/scene-format.md``).

    Parameters
    ----------
    folder : str or path-like
        Holds ``left.png``, ``right.png`` and ``meta.json`` (with ``d_max`` and optionally
        ``init_ellipse`` or ``init_point``); the ground-truth files are optional.

    Returns
    -------
    Scene
        Absent optional files give None.

    Raises
    ------
    FileNotFoundError
        The folder, ``meta.json``, ``left.png`` or ``right.png`` is missing.
    ValueError
        A file is unreadable or its size differs from ``left.png``.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"scene: folder not found: {folder}")
    meta = _read_meta(folder)
    left = read_image(folder / "left.png", f"scene {folder}: left.png")
    right = read_image(folder / "right.png", f"scene {folder}: right.png")
    shape = left.shape[:2]

    def check(a, file):
        if a.shape[:2] != shape:
            raise ValueError(f"scene {folder}: {file} has size {a.shape[:2]}, left.png {shape}")
        return a

    check(right, "right.png")
    masks = {k: check(read_mask(folder / f"{k}.png", f"scene {folder}: {k}.png"), f"{k}.png")
             for k in _MASK_FILES if (folder / f"{k}.png").is_file()}
    disp = folder / "disp_left.pfm"
    layers = folder / "layers_left.png"
    cyc = meta.get("init_ellipse_cyclopean")
    return Scene(
        name=str(meta.get("name", folder.name)), left=left, right=right,
        d_max=float(meta["d_max"]),
        init_ellipse=(None if meta.get("init_ellipse") is None else
                      _ellipse(meta["init_ellipse"], f"scene {folder}: init_ellipse")),
        init_ellipse_cyclopean=(None if cyc is None else
                                _ellipse(cyc, f"scene {folder}: init_ellipse_cyclopean")),
        init_point=(None if meta.get("init_point") is None else
                    _point(meta["init_point"], f"scene {folder}: init_point")),
        disp_left=check(read_pfm(disp), "disp_left.pfm") if disp.is_file() else None,
        layers_left=(check(_read_layers(layers, f"scene {folder}: layers_left.png"),
                           "layers_left.png") if layers.is_file() else None),
        meta=meta, path=str(folder), **masks)


def save_scene(folder, scene: Scene) -> Path:
    """Write ``scene`` as a scene folder readable by :func:`load_scene`; returns the folder.

    The folder is created if needed.  Images are rounded to 8 bits; ground-truth fields that are
    None are not written; ``meta.json`` is ``scene.meta`` updated with the name, size, ``d_max``
    and the initial ellipses and point (those that are not None).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    write_png(folder / "left.png", _to_uint8(scene.left))
    write_png(folder / "right.png", _to_uint8(scene.right))
    if scene.disp_left is not None:
        write_pfm(folder / "disp_left.pfm", scene.disp_left)
    for k in _MASK_FILES:
        if getattr(scene, k) is not None:
            write_mask(folder / f"{k}.png", getattr(scene, k))
    if scene.layers_left is not None:
        write_png(folder / "layers_left.png", np.asarray(scene.layers_left))
    h, w = scene.left.shape[:2]
    meta = {**scene.meta, "name": scene.name, "width": int(w), "height": int(h),
            "d_max": float(scene.d_max)}
    for key in ("init_ellipse", "init_ellipse_cyclopean", "init_point"):
        if getattr(scene, key) is not None:
            meta[key] = [float(v) for v in getattr(scene, key)]
    (folder / "meta.json").write_text(json.dumps(meta, indent=1))
    return folder


def list_scenes(dataset_dir) -> list:
    """Scene folders (sub-folders holding ``meta.json``) of ``dataset_dir``, sorted by name.

    Raises
    ------
    FileNotFoundError
        ``dataset_dir`` is not a folder.
    ValueError
        It holds no scene folder.
    """
    root = Path(dataset_dir)
    if not root.is_dir():
        raise FileNotFoundError(f"dataset: folder not found: {root}")
    scenes = sorted(p for p in root.iterdir() if p.is_dir() and (p / "meta.json").is_file())
    if not scenes:
        raise ValueError(f"dataset: no scene folders (sub-folders holding meta.json) in {root}")
    return scenes
