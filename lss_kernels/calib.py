"""The rectified cameras' calibration: what turns a left-view disparity into metric depth.

For a rectified pair of focal length ``f`` (pixels) and baseline ``B``, a left pixel of
disparity ``d`` lies at depth

    Z = f B / (d + doffs)

with ``doffs`` the x-difference of the two principal points (``cx1 - cx0``, Middlebury's
``doffs``; 0 when the principal points coincide).  Z has the unit of B: give the baseline in
metres for depth in metres.  The point of left pixel ``(x, y)`` (0-based, x to the right, y
down) is ``X = (x - cx) Z / f``, ``Y = (y - cy) Z / f``: the left camera's frame, x right, y
down, z forward.

:func:`read_calib` reads Middlebury's ``calib.txt``::

    cam0=[3997.684 0 1176.728; 0 3997.684 1011.728; 0 0 1]
    cam1=[3997.684 0 1307.839; 0 3997.684 1011.728; 0 0 1]
    doffs=131.111
    baseline=193.001
    width=2964
    height=1988
    ndisp=280

Every check fails with one line naming the file or argument, what was expected and what
was given.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["Calibration", "read_calib"]

#: Keys of Middlebury's calib.txt that are read; the others it may hold (isint, vmin, vmax,
#: dyavg, dymax) say nothing about the geometry and are accepted unread.
_NEEDED = ("cam0", "cam1", "doffs", "baseline")
_KNOWN = _NEEDED + ("width", "height", "ndisp", "isint", "vmin", "vmax", "dyavg", "dymax")
#: Pixels: principal points and focal lengths that agree within this are the same.
_SAME = 1e-3


def _positive(value, name):
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) \
            or not math.isfinite(value) or value <= 0:
        raise ValueError(f"{name}: expected a finite number > 0, got {value!r}")
    return float(value)


def _finite(value, name):
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) \
            or not math.isfinite(value):
        raise ValueError(f"{name}: expected a finite number, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class Calibration:
    """A rectified pair's intrinsics and baseline (validated on construction).

    Attributes
    ----------
    focal : float
        Focal length of both cameras, pixels (> 0).
    baseline : float
        Distance between the optical centres (> 0), in the unit wanted for depth.
    cx, cy : float or None
        The left camera's principal point, pixels; None: the image's centre.
    doffs : float
        ``cx1 - cx0``, pixels: the disparity of a point at infinity, negated.
    width, height : int or None
        The image size the calibration is for (None: any).
    """

    focal: float
    baseline: float
    cx: float | None = None
    cy: float | None = None
    doffs: float = 0.0
    width: int | None = None
    height: int | None = None

    def __post_init__(self):
        object.__setattr__(self, "focal", _positive(self.focal, "focal"))
        object.__setattr__(self, "baseline", _positive(self.baseline, "baseline"))
        object.__setattr__(self, "doffs", _finite(self.doffs, "doffs"))
        for name in ("cx", "cy"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, _finite(getattr(self, name), name))
        for name in ("width", "height"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, bool) or int(value) != value
                                      or value < 1):
                raise ValueError(f"{name}: expected an integer >= 1, got {value!r}")

    def check_size(self, shape, name="calib"):
        """Raise unless the calibration is for images of ``shape`` ``(H, W)``."""
        H, W = shape[:2]
        if (self.width is not None and self.width != W) or \
                (self.height is not None and self.height != H):
            raise ValueError(f"{name}: expected a calibration of the {W}x{H} images, got one "
                             f"of {self.width}x{self.height} (rescale its focal length, "
                             f"principal point and doffs, or give --focal and --baseline)")

    def principal_point(self, shape):
        """``(cx, cy)``: the given one, else the centre of an ``(H, W)`` image."""
        H, W = shape[:2]
        return (((W - 1) / 2.0 if self.cx is None else self.cx),
                ((H - 1) / 2.0 if self.cy is None else self.cy))

    def depth(self, disparity):
        """Depth ``Z = focal * baseline / (d + doffs)`` of a left-view disparity map, float32
        ``(H, W)`` in the baseline's unit; inf where ``d + doffs <= 0`` or d is not
        finite (unknown, or at infinity)."""
        d = np.asarray(disparity, np.float64) + self.doffs
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(np.isfinite(d) & (d > 0), self.focal * self.baseline / d, np.inf)
        return z.astype(np.float32)

    def points(self, disparity, mask=None):
        """The 3-D points (left camera frame: x right, y down, z forward; the baseline's
        unit) of the pixels of ``mask`` (default: all) whose depth is finite.

        Returns
        -------
        xyz : ndarray, float32, shape (N, 3)
            In row-major order of the pixels.
        pixels : ndarray, bool, shape (H, W)
            The pixels that gave a point (``mask`` and a finite depth).
        """
        z = self.depth(disparity).astype(np.float64)
        keep = np.isfinite(z) if mask is None else (np.asarray(mask, bool) & np.isfinite(z))
        cx, cy = self.principal_point(z.shape)
        ys, xs = np.nonzero(keep)
        zs = z[ys, xs]
        xyz = np.stack([(xs - cx) * zs / self.focal, (ys - cy) * zs / self.focal, zs], axis=1)
        return xyz.astype(np.float32), keep


def _matrix(text, key, where):
    """``[fx 0 cx; 0 fy cy; 0 0 1]`` -> ``(f, cx, cy)``."""
    rows = [r.split() for r in text.strip().strip("[]").split(";")]
    try:
        m = np.array([[float(v) for v in r] for r in rows])
    except ValueError:
        m = np.zeros((0, 0))
    if m.shape != (3, 3) or not np.isfinite(m).all():
        raise ValueError(f"{where}: {key}: expected a 3x3 matrix [f 0 cx; 0 f cy; 0 0 1], "
                         f"got {text!r}")
    if abs(m[0, 0] - m[1, 1]) > _SAME or m[0, 1] or m[1, 0] or (m[2] != (0, 0, 1)).any():
        raise ValueError(f"{where}: {key}: expected a rectified camera [f 0 cx; 0 f cy; "
                         f"0 0 1] (equal focal lengths, no skew), got {text!r}")
    if m[0, 0] <= 0:
        raise ValueError(f"{where}: {key}: expected a focal length > 0, got {m[0, 0]:g}")
    return m[0, 0], m[0, 2], m[1, 2]


def read_calib(path) -> Calibration:
    """Read Middlebury's ``calib.txt`` (``key=value`` lines; see the module docstring).

    Needs ``cam0``, ``cam1``, ``doffs`` and ``baseline``; ``width`` and ``height``, when
    given, are checked against the images (:meth:`Calibration.check_size`).  The two
    cameras must share their focal length and principal row (a rectified pair), and doffs
    must be ``cx1 - cx0``.

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        One line naming the file and the key: a line that is not ``key=value``, an unknown
        or missing key, a value that is not a number, or cameras that are not one
        rectified pair.
    """
    path = Path(path)
    where = f"calib {path}"
    if not path.is_file():
        raise FileNotFoundError(f"calib: file not found: {path}")
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{where}: could not read as text ({exc})") from exc
    values = {}
    for number, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        key, sep, value = (part.strip() for part in line.partition("="))
        if not sep or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", key):
            raise ValueError(f"{where}: line {number}: expected key=value, got {line.strip()!r}")
        if key not in _KNOWN:
            raise ValueError(f"{where}: unknown key {key!r}; expected {', '.join(_KNOWN)}")
        values[key] = value
    missing = [k for k in _NEEDED if k not in values]
    if missing:
        raise ValueError(f"{where}: missing {', '.join(missing)}; expected "
                         f"{', '.join(_NEEDED)}")

    def number(key):
        try:
            value = float(values[key])
        except ValueError:
            raise ValueError(f"{where}: {key}: expected a number, got {values[key]!r}") from None
        if not math.isfinite(value):
            raise ValueError(f"{where}: {key}: expected a finite number, got {values[key]!r}")
        return value

    f0, cx0, cy0 = _matrix(values["cam0"], "cam0", where)
    f1, cx1, cy1 = _matrix(values["cam1"], "cam1", where)
    if abs(f0 - f1) > _SAME:
        raise ValueError(f"{where}: expected cam0 and cam1 of one focal length (a rectified "
                         f"pair), got {f0:g} and {f1:g}")
    if abs(cy0 - cy1) > _SAME:
        raise ValueError(f"{where}: expected cam0 and cam1 of one principal row cy (a "
                         f"rectified pair), got {cy0:g} and {cy1:g}")
    doffs = number("doffs")
    if abs(doffs - (cx1 - cx0)) > _SAME:
        raise ValueError(f"{where}: doffs: expected cx1 - cx0 = {cx1 - cx0:g}, got {doffs:g}")
    baseline = number("baseline")
    if baseline <= 0:
        raise ValueError(f"{where}: baseline: expected a number > 0, got {baseline:g}")
    size = {}
    for key in ("width", "height"):
        if key in values:
            value = number(key)
            if value != int(value) or value < 1:
                raise ValueError(f"{where}: {key}: expected an integer >= 1, got "
                                 f"{values[key]!r}")
            size[key] = int(value)
    return Calibration(focal=f0, baseline=baseline, cx=cx0, cy=cy0, doffs=doffs, **size)
