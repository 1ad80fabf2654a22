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
  the foreground (the "foreground" is not in front);
- the foreground surface leaves the searched disparity range ``[0, d_max]`` on more than
  ``MAX_OUT_OF_RANGE`` of the foreground (no match there supports it: on periodic texture a
  quadratic bent far out of range can still explain the stripes).

The pair is then solved again with the parameters changed by ``RECOVERY``: the AD-Census
cost (it matches dark and low-contrast texture by the order of grey values) and messages
weighted by the distinctness of their cost curves (a periodic texture's patches, whose
curves have several equally deep minima, send almost none; ``Params.message_ambiguity``).
The second model is kept when it is sound; otherwise the first stays.  ``Result.recovery``
records what happened.

Neither change is the default: on the paper's scenes AD-Census lowers the mean occlusion F1
from 0.79 to 0.76 and the distinctness weights to 0.76 (``docs/design.md``).
"""
import numpy as np

from .model.init import InitError

__all__ = ["MAX_CROSSING", "MAX_OUT_OF_RANGE", "MIN_JUMP", "RECOVERY", "collapse",
           "model_health", "with_recovery"]

#: Smallest mean disparity jump (left-view pixels) over the foreground of a sound model.
MIN_JUMP = 1.0
#: Largest fraction of the foreground where Theta_1 <= Theta_2 in a sound model.
MAX_CROSSING = 0.5
#: Largest fraction of the foreground where Theta_1 lies outside [0, d_max] in a sound model.
MAX_OUT_OF_RANGE = 0.02
#: The parameters of the second solve.
RECOVERY = {"matching_cost": "ad_census", "message_ambiguity": 0.2}


def model_health(result, d_max) -> dict:
    """``area`` (foreground fraction, cyclopean), ``jump`` (mean left-view jump over the
    foreground), ``crossing`` (fraction of the foreground where Theta_1 <= Theta_2) and
    ``out_of_range`` (fraction of the foreground where Theta_1 is outside ``[0, d_max]``)."""
    fg = np.asarray(result.phi) > 0
    if not fg.any():
        return {"area": 0.0, "jump": 0.0, "crossing": 1.0, "out_of_range": 0.0}
    y, x = np.nonzero(fg)
    x, y = x.astype(np.float64), y.astype(np.float64)
    basis = np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], axis=-1)
    front = basis @ np.asarray(result.theta_fg, np.float64)
    jump = front - basis @ np.asarray(result.theta_bg, np.float64)
    return {"area": float(fg.mean()), "jump": float(jump.mean()),
            "crossing": float((jump <= 0).mean()),
            "out_of_range": float(((front < 0) | (front > float(d_max))).mean())}


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
    if health["out_of_range"] > MAX_OUT_OF_RANGE:
        return (f"the foreground surface leaves [0, d_max] on {health['out_of_range']:.0%} "
                f"of the foreground (> {MAX_OUT_OF_RANGE:.0%})")
    return None


def with_recovery(run, params, d_max):
    """``run(params) -> (result, extra)`` once, and again with ``RECOVERY`` when the
    first model collapsed (and ``params.recover``); returns the ``(result, extra)`` kept,
    with ``result.recovery`` set.  ``params`` None: the defaults; ``d_max``: the searched
    range (left-view pixels)."""
    from .params import Params
    params = Params() if params is None else params
    result, extra = run(params)
    first = model_health(result, d_max)
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
    second = model_health(second_result, d_max)
    second_reason = collapse(second)
    record.update(retry_health=second, retry_collapse=second_reason,
                  kept="first" if second_reason else "retry")
    if second_reason is None:
        second_result.recovery = record
        return second_result, second_extra
    result.recovery = record
    return result, extra
