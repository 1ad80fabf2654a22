"""A collapsed solve is recognised from its own model and solved again with safer parameters.

On weak, dark or periodic textures the paper's absolute-difference cost (Sec. 4) can lead
the alternation to a model that explains nothing: the foreground vanishes or fills the image,
or the two surfaces coincide or cross, so that no disparity jump and no occlusion remain
(Sec. 2: the occluded extent *is* the jump).  Such a model is recognised without ground
truth:

- the foreground (phi > 0) is empty or the whole image;
- the mean jump ``2 (Theta_1 - Theta_2)`` over the foreground is below ``MIN_JUMP``
  left-view pixels;
- the foreground surface lies at or behind the background on more than ``MAX_CROSSING`` of
  the foreground (the "foreground" is not in front).

The pair is then solved again with the parameters changed by ``RECOVERY``: the AD-Census
cost (it matches dark and low-contrast texture by the order of grey values) and messages
weighted by the distinctness of their cost curves (a periodic texture's patches, whose
curves have several equally deep minima, send almost none; ``Params.message_ambiguity``).
The second model is kept only when it is sound and has a larger jump and less crossing than
the first; otherwise the first stays.  ``Result.recovery`` records what happened.

Neither change is the default: on the paper's scenes AD-Census lowers the mean occlusion F1
from 0.79 to 0.76 and the distinctness weights to 0.76 (``docs/design.md``).
"""
import numpy as np

from .model.init import InitError

__all__ = ["MAX_CROSSING", "MIN_JUMP", "RECOVERY", "collapse", "model_health",
           "with_recovery"]

#: Smallest mean disparity jump (left-view pixels) over the foreground of a sound model.
MIN_JUMP = 1.0
#: Largest fraction of the foreground where Theta_1 <= Theta_2 in a sound model.
MAX_CROSSING = 0.5
#: The parameters of the second solve.
RECOVERY = {"matching_cost": "ad_census", "message_ambiguity": 0.2}


def model_health(result) -> dict:
    """``area`` (foreground fraction, cyclopean), ``jump`` (mean left-view jump over the
    foreground) and ``crossing`` (fraction of the foreground where Theta_1 <= Theta_2)."""
    fg = np.asarray(result.phi) > 0
    if not fg.any():
        return {"area": 0.0, "jump": 0.0, "crossing": 1.0}
    y, x = np.nonzero(fg)
    x, y = x.astype(np.float64), y.astype(np.float64)
    basis = np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], axis=-1)
    jump = basis @ (np.asarray(result.theta_fg, np.float64)
                    - np.asarray(result.theta_bg, np.float64))
    return {"area": float(fg.mean()), "jump": float(jump.mean()),
            "crossing": float((jump <= 0).mean())}


def collapse(health: dict):
    """Why a model (:func:`model_health`) has collapsed, or None when it is sound."""
    if health["area"] == 0.0:
        return "the foreground vanished"
    if health["area"] == 1.0:
        return "the foreground filled the image"
    if health["jump"] < MIN_JUMP:
        return (f"the surfaces coincide: mean jump {health['jump']:.2f} px over the "
                f"foreground (< {MIN_JUMP})")
    if health["crossing"] > MAX_CROSSING:
        return (f"the foreground lies behind the background on {health['crossing']:.0%} "
                f"of it (> {MAX_CROSSING:.0%})")
    return None


def with_recovery(run, params):
    """``run(params) -> (result, extra)`` once, and again with ``RECOVERY`` when the
    first model collapsed (and ``params.recover``); returns the ``(result, extra)`` kept,
    with ``result.recovery`` set.  ``params`` None: the defaults."""
    from .params import Params
    params = Params() if params is None else params
    result, extra = run(params)
    first = model_health(result)
    reason = collapse(first)
    record = {"health": first, "collapse": reason, "retried": False}
    second_params = params.replace(**RECOVERY)
    if reason is None or not params.recover or second_params == params:
        result.recovery = record
        return result, extra
    record.update(retried=True, retry_params=dict(RECOVERY))
    try:
        second_result, second_extra = run(second_params)
    except InitError as error:         # e.g. auto finds no object in the census consensus
        record.update(retry_error=str(error), kept="first")
        result.recovery = record
        return result, extra
    second = model_health(second_result)
    kept = (collapse(second) is None and second["jump"] > first["jump"]
            and second["crossing"] <= first["crossing"])
    record.update(retry_health=second,
                  retry_collapse=collapse(second), kept="retry" if kept else "first")
    if kept:
        second_result.recovery = record
        return second_result, second_extra
    result.recovery = record
    return result, extra
