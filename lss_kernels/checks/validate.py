"""Validation at the API boundary: every check names the argument, what was expected and what
was given, so that bad input never reaches a kernel."""
import math
import numbers
import os

import numpy as np

from ..start_types import AUTO, Box, Point

__all__ = ["LUMA", "available_memory", "check_init", "check_inputs", "check_memory",
           "check_pair", "check_params", "check_range", "fields_bytes", "luma", "parse_init"]

#: The smallest radius of an initial ellipse, pixels: one with a radius below it covers at
#: most one pixel along that axis, no region to start from (a start's 7x7 median erases it).
MIN_RADIUS = 1.0
KINDS = "expected an ellipse (cx, cy, rx, ry), a boolean mask, 'auto', a Point or a Box"


def _largest_patch(params):
    return max(params.patch_sizes)


def check_params(params):
    """``params`` itself, or the defaults for None; a ``TypeError`` for anything but a
    :class:`~lss_kernels.Params`."""
    from ..params import Params
    if params is None:
        return Params()
    if not isinstance(params, Params):
        raise TypeError(f"params: expected lss_kernels.Params, got {type(params).__name__}")
    return params


def check_inputs(left, right, d_max, init, init_frame, params):
    """Read and check the solver's inputs; returns ``(left, right, d_max, init)`` with the
    images as float32 ``(H, W, 3)`` in [0, 1] and ``init`` as an ellipse tuple or a boolean
    mask."""
    left, right = check_pair(left, right)
    H, W = left.shape[:2]
    need = _largest_patch(params)
    if H < need or W < need:
        raise ValueError(f"left: expected an image at least {need}x{need} pixels (the largest "
                         f"patch), got {W}x{H}")
    check_range(d_max, W)
    if init_frame not in ("left", "cyclopean"):
        raise ValueError(f"init_frame: expected 'left' or 'cyclopean', got {init_frame!r}")
    return left, right, float(d_max), check_init(init, (H, W))


#: Rec. 601 luma weights of R, G, B (what OpenCV and Pillow use to make grey images).
LUMA = np.array([0.299, 0.587, 0.114])


def luma(image) -> np.ndarray:
    """The grey image (Rec. 601 luma, float64) of an ``(H, W, C)`` RGB(A) image; an ``(H, W)``
    image as float64 itself.  The one grey of the checks (the kernels' census and Sobel
    compute the same weights on the device)."""
    image = np.asarray(image, np.float64)
    return image[..., :3] @ LUMA if image.ndim == 3 else image


def _grey(image) -> bool:
    """Whether an ``(H, W, 3)`` image has three equal channels."""
    return bool((image[..., 0] == image[..., 1]).all() and (image[..., 1] == image[..., 2]).all())


def check_pair(left, right):
    """Both images read (:func:`lss_kernels.io.read_image`) and of one size.  When one view is
    grey and the other colour, the colour one is made grey too (Rec. 601 luma): a grey pixel
    compared with a colour one differs at the true match too."""
    from ..io import read_image
    left = read_image(left, name="left")
    right = read_image(right, name="right")
    if left.shape != right.shape:
        raise ValueError(f"right: expected the size of left ({left.shape[1]}x{left.shape[0]}), "
                         f"got {right.shape[1]}x{right.shape[0]}")
    grey = _grey(left), _grey(right)
    if grey[0] != grey[1]:
        as_grey = lambda img: np.repeat(luma(img)[..., None], 3, axis=2).astype(np.float32)
        left, right = (img if g else as_grey(img) for img, g in zip((left, right), grey))
    return left, right


def check_range(d_max, width):
    """``d_max`` a finite number of pixels in ``(0, width)``."""
    if isinstance(d_max, bool) or not isinstance(d_max, numbers.Real) or not math.isfinite(d_max):
        raise ValueError(f"d_max: expected a finite number of pixels, got {d_max!r}")
    if not 0 < d_max < width:
        raise ValueError(f"d_max: expected 0 < d_max < image width ({width}), got {d_max}")


def fields_bytes(height, width, d_max) -> int:
    """About the bytes of a solver's fields for a ``width x height`` pair searched to
    ``d_max`` (the default parameters; under what they hold): per pixel of the size
    bucket, 608 bytes of planes and 16 bytes for each of the ``c_max`` candidates of the
    volumes (measured at 256x192: 703 + 17.0 c_max), and the median's scratch (25 MB up to
    1024x768)."""
    from ..kernels.backend import bucket_shape
    from ..kernels.median import scratch_bytes
    from ..params import c_max
    bucket_h, bucket_w = bucket_shape(int(height), int(width))
    return (bucket_h * bucket_w * (608 + 16 * c_max(d_max))
            + scratch_bytes((bucket_h, bucket_w)))


def available_memory():
    """Bytes of memory this machine can still give a process (``MemAvailable`` on Linux, the
    free pages elsewhere), or None where neither can be read."""
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None


def check_memory(height, width, d_max):
    """On the CPU, a pair whose solver's fields (:func:`fields_bytes`) would not fit in the
    memory available is refused before any is allocated (instead of the process being
    killed part-way); a new :class:`~lss_kernels.Solver` asks, a reset one (its fields
    already allocated) does not."""
    from ..kernels.backend import current_arch
    if current_arch() not in (None, "cpu"):
        return
    need, have = fields_bytes(height, width, d_max), available_memory()
    if have is not None and need > have:
        raise ValueError(f"left: a {width}x{height} pair searched to d_max {d_max:g} needs about "
                         f"{need / 2**30:.1f} GiB for the solver's fields and this machine has "
                         f"{have / 2**30:.1f} GiB available; expected a smaller pair: "
                         f"downscale both images and d_max by one factor, or crop them")


def _describe(value):
    """A short one-line description of a value for error messages (arrays by shape)."""
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape} ({value.dtype})"
    text = repr(value).replace("\n", " ")
    return text if len(text) <= 60 else text[:57] + "..."


def check_init(init, shape):
    """An ellipse ``(cx, cy, rx, ry)`` with radii of at least ``MIN_RADIUS`` pixels that covers
    a pixel of the image (a pixel centre ``(x, y)`` with ``((x - cx) / rx)^2 + ((y - cy) /
    ry)^2 <= 1``), or a non-empty boolean mask of the image's shape.

    Parameters
    ----------
    init : sequence of 4 numbers, or array-like ``(H, W)``
        The ellipse in pixel coordinates (0-based, x to the right, y down), or a mask (bool,
        or numbers where nonzero means foreground).
    shape : (int, int)
        ``(H, W)`` of the images.

    Returns
    -------
    tuple of 4 float, or ndarray bool ``(H, W)``

    Raises
    ------
    ValueError
        One line naming ``init``, what was expected and what was given.
    """
    H, W = shape
    if isinstance(init, str) and init == AUTO:
        return init
    if isinstance(init, Point):
        if not (math.isfinite(init.x) and math.isfinite(init.y)
                and 0 <= init.x <= W - 1 and 0 <= init.y <= H - 1):
            raise ValueError(f"init: expected a point inside the {W}x{H} image "
                             f"(0 <= x <= {W - 1}, 0 <= y <= {H - 1}), got ({init.x:g}, {init.y:g})")
        return Point(float(init.x), float(init.y))
    if isinstance(init, Box):
        x0, y0, x1, y1 = init.x0, init.y0, init.x1, init.y1
        if not all(math.isfinite(v) for v in (x0, y0, x1, y1)) or x1 <= x0 or y1 <= y0:
            raise ValueError(f"init: expected a box with x0 < x1 and y0 < y1 (positive area), "
                             f"got ({x0:g}, {y0:g}, {x1:g}, {y1:g})")
        if x0 < 0 or y0 < 0 or x1 > W or y1 > H:
            raise ValueError(f"init: expected a box inside the {W}x{H} image, got "
                             f"({x0:g}, {y0:g}, {x1:g}, {y1:g})")
        return Box(float(x0), float(y0), float(x1), float(y1))
    if isinstance(init, (str, bytes)):
        raise ValueError(f"init: {KINDS}, got the string {_describe(init)}")
    if not isinstance(init, np.ndarray):
        try:
            as_array = np.asarray(init)
        except Exception:  # ragged or exotic sequences: reported as not an ellipse below
            as_array = None
        if as_array is not None and as_array.ndim >= 2:
            init = as_array
    if isinstance(init, np.ndarray) and init.ndim != 1:
        if init.ndim != 2 or init.shape != (H, W):
            raise ValueError(f"init: expected a mask of shape {(H, W)}, got shape {init.shape}")
        if init.dtype == bool:
            mask = init
        elif np.issubdtype(init.dtype, np.number):
            if not np.isfinite(init).all():
                raise ValueError("init: expected a mask of finite values, got NaN or inf")
            mask = init != 0
        else:
            raise ValueError(f"init: expected a boolean or numeric mask, got dtype {init.dtype}")
        if not mask.any():
            raise ValueError("init: the mask is empty (no foreground pixel)")
        if mask.all():
            raise ValueError("init: the mask covers the whole image (no background pixel)")
        return np.ascontiguousarray(mask, dtype=bool)
    try:
        values = tuple(float(v) for v in init)
    except (TypeError, ValueError):
        raise ValueError(f"init: {KINDS}, got {_describe(init)}") from None
    if len(values) != 4:
        raise ValueError(f"init: expected an ellipse of 4 numbers (cx, cy, rx, ry), "
                         f"got {len(values)}")
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"init: expected finite numbers, got {values}")
    cx, cy, rx, ry = values
    if rx < MIN_RADIUS or ry < MIN_RADIUS:
        raise ValueError(f"init: expected radii of at least {MIN_RADIUS:g} pixel, got "
                         f"rx={rx:g}, ry={ry:g}")
    y, x = np.mgrid[0:H, 0:W]
    with np.errstate(over="ignore"):       # a centre far away: the distances overflow to inf
        covers = (((x - cx) / rx) ** 2 + ((y - cy) / ry) ** 2 <= 1.0).any()
    if covers:
        return values
    if not (-rx < cx < W - 1 + rx and -ry < cy < H - 1 + ry):
        raise ValueError(f"init: the ellipse centred at ({cx:g}, {cy:g}) with radii "
                         f"({rx:g}, {ry:g}) lies outside the {W}x{H} image")
    raise ValueError(f"init: the ellipse ({cx:g}, {cy:g}, {rx:g}, {ry:g}) covers no pixel "
                     f"of the {W}x{H} image")


def _numbers(text, rest, count, form):
    try:
        values = tuple(float(p) for p in rest.split(","))
    except ValueError:
        values = ()
    if len(values) != count:
        raise ValueError(f"--init: expected {form} with {count} numbers, got {text!r}")
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"--init: expected {count} finite numbers, got {text!r}")
    return values


def parse_init(text):
    """Parse the CLI's ``--init``: ``auto``, ``point:X,Y``, ``box:X0,Y0,X1,Y1``,
    ``ellipse:CX,CY,RX,RY`` or ``mask:PATH`` (or a PNG path); left-view pixels."""
    if not isinstance(text, str) or not text:
        raise ValueError(f"--init: expected auto, point:X,Y, box:X0,Y0,X1,Y1, "
                         f"ellipse:CX,CY,RX,RY or mask:PATH, got {text!r}")
    kind, _, rest = text.partition(":")
    if text == AUTO:
        return AUTO
    if kind == "point":
        return Point(*_numbers(text, rest, 2, "point:X,Y"))
    if kind == "box":
        return Box(*_numbers(text, rest, 4, "box:X0,Y0,X1,Y1"))
    if kind == "ellipse":
        return _numbers(text, rest, 4, "ellipse:CX,CY,RX,RY")
    if kind == "mask" or text.lower().endswith(".png"):
        from ..io import read_mask
        if kind == "mask" and not rest:
            raise ValueError(f"--init: expected mask:PATH with a path, got {text!r}")
        return read_mask(rest if kind == "mask" else text, name="--init")
    raise ValueError(f"--init: unknown kind {kind!r}; expected auto, point:X,Y, "
                     f"box:X0,Y0,X1,Y1, ellipse:CX,CY,RX,RY or mask:PATH")
