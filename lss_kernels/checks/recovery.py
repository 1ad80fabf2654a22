"""Safer parameters for pairs the paper's defaults cannot solve: periodic texture is recognised
before the solve, a collapsed model after it.

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
  quadratic bent far out of range can still explain the stripes);
- the background surface lies more than ``MAX_OFFSET`` left-view pixels from the
  background's own matches: the median over its visible pixels of the refined disparity
  (:mod:`lss_kernels.model.refine`, which searches +-24 px around the surface with the
  AD-Census cost) minus the surface.  On a dark, weakly textured background the AD cost can
  let Theta_2 drift towards Theta_1 while a jump of a few pixels remains: the boundary is
  right, the occlusion as narrow as the false jump, and the matches say so.  The
  foreground's offset is reported but not judged: on a striped foreground the refinement's
  matches can themselves lie a period off.

The pair is then solved again with the parameters changed by ``RECOVERY``: the AD-Census
cost (it matches dark and low-contrast texture by the order of grey values) and messages
weighted by the distinctness of their cost curves (a periodic texture's patches, whose
curves have several equally deep minima, send almost none; ``Params.message_ambiguity``).
The second model is kept when it is sound; otherwise the first stays.  ``Result.recovery``
records what happened, and a model kept collapsed warns :class:`CollapsedModelWarning`: its
output is no two-layer reading of the pair (a layer with too little texture, or texture lost
in noise, ``docs/stress.md``).

Neither change is the default: each costs occlusion F1 on the paper's scenes.

A periodic texture does not always collapse the model: the stripes can be explained by a
sound-looking model at the wrong disparity, whose boundary wanders over the background.  So
the left image is examined first (:mod:`lss_kernels.checks.periodicity`).  When at least
``PERIODIC_AREA`` of its tiles are periodic, the first solve
uses ``PERIODIC`` -- ``RECOVERY`` without the refinement, whose residuals need distinct
matches (on stripes they lie whole periods off) -- and the retry, if its model collapses,
the given parameters.  Each solve of a periodic pair then has its foreground moved to the
tooth whose outline the right image shows (:mod:`lss_kernels.checks.teeth`, recorded as
``tooth``) before its model is judged.
"""
import contextlib
import warnings

import numpy as np

from ..model.quadratic import evaluate
from ..start_types import InitError, UnreliableStartWarning
from .periodicity import PERIODIC_AREA

__all__ = ["CollapsedModelWarning", "MAX_CROSSING", "MAX_OFFSET", "MAX_OUT_OF_RANGE",
           "MIN_JUMP", "PERIODIC", "RECOVERY", "ShortRangeWarning", "SwappedViewsWarning",
           "UnreliableStartWarning", "WARNINGS", "collapse", "layer_offsets", "model_health",
           "named_warnings", "with_recovery"]

#: Smallest mean disparity jump (left-view pixels) over the foreground of a sound model.
MIN_JUMP = 1.0
#: Largest fraction of the foreground where Theta_1 <= Theta_2 in a sound model.
MAX_CROSSING = 0.5
#: Largest fraction of the foreground where Theta_1 lies outside [0, d_max] in a sound model.
MAX_OUT_OF_RANGE = 0.02
#: Largest median distance (left-view pixels) of the background's refined disparity from
#: its surface in a sound model (bad-4.0's threshold).
MAX_OFFSET = 4.0
#: The parameters of the second solve.
RECOVERY = {"matching_cost": "ad_census", "message_ambiguity": 0.2}
#: The parameters of the first solve of a periodic pair.
PERIODIC = {**RECOVERY, "refine": False}
def model_health(result, d_max) -> dict:
    """``area`` (foreground fraction, cyclopean), ``jump`` (mean left-view jump over the
    foreground), ``crossing`` (fraction of the foreground where Theta_1 <= Theta_2),
    ``out_of_range`` (fraction of the foreground where Theta_1 is outside ``[0, d_max]``) and
    ``offset_fg``, ``offset_bg`` (per layer, the median of the refined disparity minus the
    surface over the layer's visible left-view pixels; 0 for an empty layer, and for a
    result without refinement, whose disparity is its surface)."""
    offsets = layer_offsets(result)
    fg = np.asarray(result.phi) > 0
    if not fg.any():
        return {"area": 0.0, "jump": 0.0, "crossing": 1.0, "out_of_range": 0.0, **offsets}
    y, x = np.nonzero(fg)
    x, y = x.astype(np.float64), y.astype(np.float64)
    front = evaluate(result.theta_fg, x, y)
    jump = front - evaluate(result.theta_bg, x, y)
    return {"area": float(fg.mean()), "jump": float(jump.mean()),
            "crossing": float((jump <= 0).mean()),
            "out_of_range": float(((front < 0) | (front > float(d_max))).mean()), **offsets}


def layer_offsets(result) -> dict:
    """``offset_fg``, ``offset_bg``: per layer (``result.foreground`` and the rest), the
    median of ``result.disparity - result.surface`` over the layer's pixels outside
    ``result.occlusion`` (left view); 0 where the layer has none."""
    residual = np.asarray(result.disparity, np.float64) - np.asarray(result.surface, np.float64)
    foreground = np.asarray(result.foreground, bool)
    visible = ~np.asarray(result.occlusion, bool)
    offsets = {}
    for name, layer in (("offset_fg", foreground), ("offset_bg", ~foreground)):
        values = residual[layer & visible]
        offsets[name] = float(np.median(values)) if values.size else 0.0
    return offsets


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
    if abs(health["offset_bg"]) > MAX_OFFSET:
        return (f"the background surface lies {health['offset_bg']:+.1f} px from its own "
                f"matches (median over its visible pixels; more than {MAX_OFFSET:g})")
    return None


class SwappedViewsWarning(UserWarning):
    """The pair's matches run the other way: the right image was probably passed first."""


class ShortRangeWarning(UserWarning):
    """Many of the pair's matches lie beyond the searched range: ``d_max`` is too small."""


class CollapsedModelWarning(UserWarning):
    """The model returned collapsed (:func:`collapse`), and no other solve gave a sound one:
    the output is no two-layer reading of the pair."""


#: The library's own warnings, which the commands show every time.
WARNINGS = (SwappedViewsWarning, ShortRangeWarning, UnreliableStartWarning,
            CollapsedModelWarning)


def _kept(result, extra, record):
    """``(result, extra)`` with ``result.recovery = record``; warns when the model kept is
    collapsed."""
    result.recovery = record
    # a retry is kept only when it is sound; anything else kept is the first model
    reason = None if record.get("kept") == "retry" else record["collapse"]
    if reason is not None:
        again = ", ".join(f"{k}={v}" for k, v in record.get("retry_params", {}).items())
        retry = (f"; so did the solve again with {again} "
                 f"({record.get('retry_collapse') or record.get('retry_error')})"
                 if record["retried"] else "")
        warnings.warn(CollapsedModelWarning(
            f"no sound model: {reason}{retry}; the output is no two-layer reading of the pair "
            f"(a layer with too little texture, or texture lost in noise?)"), stacklevel=3)
    return result, extra


@contextlib.contextmanager
def named_warnings(name: str):
    """Inside, the library's own warnings (:data:`WARNINGS`) are held and given again on
    leaving as ``"<name>: <message>"``, so that a line of ``lss eval`` or ``lss batch`` says
    which pair it is about; other warnings are shown as they were."""
    ours, held = WARNINGS, []
    try:
        with warnings.catch_warnings(record=True) as caught:
            for category in ours:
                warnings.simplefilter("always", category)
            try:
                yield
            finally:
                held = list(caught)
    finally:                            # also when the solve fails: the warning may say why
        for w in held:
            if issubclass(w.category, ours):
                warnings.warn(w.category(f"{name}: {w.message}"), stacklevel=3)
            else:
                warnings.showwarning(w.message, w.category, w.filename, w.lineno)


def _check_matches(pair) -> tuple:
    """The pair's :attr:`~.pair.CheckedPair.direction` and, unless swapped, its
    :attr:`~.pair.CheckedPair.range`; warns when swapped or when the range looks too
    short.  A periodic pair (``PERIODIC_AREA`` of its tiles) is never swapped
    (``direction["periodic"]``): each match has teeth a period apart on both sides of 0,
    and which direction's teeth fall nearer whole pixels (what the check's integer shifts
    compare) is chance (``periodic_same_coarse`` of ``lss_kernels.stress --periodic --seed
    1``: 86 % of its textured pixels won the other way)."""
    direction = pair.direction
    if direction["swapped"] and pair.periodic >= PERIODIC_AREA:
        direction = {**direction, "swapped": False, "periodic": True}
    if direction["swapped"]:
        warnings.warn(SwappedViewsWarning(
            f"the views look swapped: the right image matches the left one at x + d on "
            f"{direction['reversed']:.0%} of its textured pixels and at x - d on "
            f"{direction['stated']:.0%}; the left image must be the reference (x_right = "
            f"x_left - d, d >= 0): pass the two images the other way round"), stacklevel=3)
        return direction, {}
    reach = pair.range
    if reach["short"]:
        warnings.warn(ShortRangeWarning(
            f"the search range looks too short: {reach['beyond']:.0%} of the textured pixels "
            f"match better at a disparity between d_max = {pair.d_max:g} and twice it than "
            f"within [0, d_max]; give a larger d_max (--dmax)"), stacklevel=3)
    return direction, reach


def _on_tooth(run, pair, record, anchor):
    """``run`` whose results are moved to the foreground's tooth
    (:func:`~lss_kernels.checks.teeth.on_tooth`), what was found recorded as ``tooth``,
    then, on a periodic object, given the layers and outline read row by row from the pair
    when they explain it better and keep ``anchor`` (a whole photo's click, or None:
    :func:`~lss_kernels.checks.outline.on_layers`, recorded as ``tooth["outline"]``)."""
    from .outline import on_layers
    from .teeth import on_tooth

    def moved(p):
        result, extra = run(p)
        result, record["tooth"] = on_tooth(result, pair.left, pair.right, pair.d_max)
        if record["tooth"].get("period") is not None:
            record["tooth"]["outline"] = on_layers(result, pair.left, pair.right, pair.d_max,
                                                   anchor)
        return result, extra
    return moved


def with_recovery(run, params, d_max, pair=None, anchor=None):
    """``run(params) -> (result, extra)`` once, and again when the model collapsed (and
    ``params.recover``); returns the ``(result, extra)`` kept, with ``result.recovery`` set.

    The first solve uses ``params`` and the second ``params`` changed by ``RECOVERY``; when
    the left image of ``pair`` (a :class:`~lss_kernels.checks.pair.CheckedPair`) is
    periodic over at least ``PERIODIC_AREA`` of its tiles, the first uses ``params``
    changed by ``PERIODIC`` and the second ``params`` (at once, without a retry, when the
    first finds no initial region: :class:`~lss_kernels.start_types.InitError`), and each
    result is moved to its foreground's tooth (:func:`~lss_kernels.checks.teeth.on_tooth`,
    recorded as ``tooth``) before it is judged.  ``params``
    None: the defaults; ``d_max``: the searched range (left-view pixels).  With ``pair``,
    it is first checked for swapped views and a search range that is too short
    (:mod:`lss_kernels.checks.direction`, recorded as ``direction`` and ``range``): a
    :class:`SwappedViewsWarning` or a :class:`ShortRangeWarning` says so before the solve.
    ``anchor``: a left-view :class:`~lss_kernels.start_types.Point` that the object must
    hold after the outline check of a periodic pair (a whole photo's click; None: none)."""
    from ..params import Params
    params = Params() if params is None else params
    record = {}
    if pair is not None:
        record["direction"], record["range"] = _check_matches(pair)
    first_params, second_params = params, params.replace(**RECOVERY)
    if params.recover and pair is not None and second_params != params:
        fraction = pair.periodic
        record["periodic"] = fraction
        if fraction >= PERIODIC_AREA:
            first_params, second_params = params.replace(**PERIODIC), params
            record["first_params"] = dict(PERIODIC)
            run = _on_tooth(run, pair, record, anchor)
    try:
        result, extra = run(first_params)
    except InitError as error:
        if first_params == params:
            raise
        # a start from the first consensus (auto, a point) found nothing with the
        # periodic parameters, whose ambiguous patches send no message: the given ones
        record.update(first_error=str(error))
        first_params = second_params
        result, extra = run(first_params)
    first = model_health(result, d_max)
    reason = collapse(first)
    record.update(health=first, collapse=reason, retried=False)
    if reason is None or not params.recover or second_params == first_params:
        return _kept(result, extra, record)
    changed = {k: v for k, v in vars(second_params).items() if getattr(first_params, k) != v}
    record.update(retried=True, retry_params=changed)
    try:
        with warnings.catch_warnings():
            # a start found automatically again, on the same left image: its warning
            # would repeat the first solve's
            warnings.simplefilter("ignore", UnreliableStartWarning)
            second_result, second_extra = run(second_params)
    except InitError as error:         # e.g. auto finds no object in the census consensus
        record.update(retry_error=str(error), kept="first")
        return _kept(result, extra, record)
    second = model_health(second_result, d_max)
    second_reason = collapse(second)
    record.update(retry_health=second, retry_collapse=second_reason,
                  kept="first" if second_reason else "retry")
    if second_reason is None:
        return _kept(second_result, second_extra, record)
    return _kept(result, extra, record)
