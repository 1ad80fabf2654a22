"""lss_kernels: two-layer level-set stereo with exact occlusion geometry (Wang & Zickler).

Public API: :func:`solve`, :class:`Solver`, :class:`Params`, :class:`Result`, the
initialisations :class:`Point` and :class:`Box` (or ``init="auto"``), :func:`solve_photo`
(one object of a whole photo, :mod:`lss_kernels.photo`), and the cameras'
:class:`Calibration` (:func:`read_calib`) for metric depth and point clouds.
Importing the package does not initialise Taichi; :func:`lss_kernels.kernels.backend.init` does.
"""
from .params import Params

__all__ = ["Box", "Calibration", "Params", "Point", "Result", "Solver", "read_calib", "solve",
           "solve_photo", "__version__"]
__version__ = "0.1.0"


def __getattr__(name):
    # The solver pulls in Taichi kernels; import it only when asked for.
    if name in ("Result", "Solver"):
        from . import solver
        return getattr(solver, name)
    if name == "solve":
        from .checks.around import solve
        return solve
    if name == "solve_photo":
        from . import photo
        return photo.solve_photo
    if name in ("Calibration", "read_calib"):
        from . import calib
        return getattr(calib, name)
    if name in ("Point", "Box"):
        from . import start_types
        return getattr(start_types, name)
    raise AttributeError(name)
