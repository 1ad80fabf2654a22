"""``Params.paper()``: the paper's method and nothing beyond it; ``Params()`` the defaults."""
import pytest

from lss_kernels import Params

#: What the recommended defaults add to the paper, and its value in the paper's method.
BEYOND_THE_PAPER = {
    "narrow_band": 0.0,                  # Eq. 2 moves phi everywhere
    "subpixel_messages": False,          # Eq. 5's argmin on the integer grid (the release)
    "background_sweep": 0.0,             # Theta_2 is the Eq. 8 fit alone
    "refine_ellipse": False,             # the start ellipse as drawn
    "refine": False,                     # the two quadratics are the output
    "strip_window": (0, 0),              # the z-buffer's occluded strips
    "photometric": False,
    "recover": False,
    "appearance": 0.0,                   # Eq. 2's data term is the matching cost alone
    "zero_floor": False,                 # the release's grid from 2 px
}


def test_paper_differs_from_the_defaults_exactly_in_what_lies_beyond_the_paper():
    paper, default = Params.paper(), Params()
    changed = {k: getattr(paper, k) for k in default.to_dict()
               if getattr(paper, k) != getattr(default, k)}
    assert changed == BEYOND_THE_PAPER


def test_paper_keeps_section_4s_values_the_ad_cost_and_no_option_of_the_recovery():
    paper = Params.paper()
    assert (paper.dt, paper.alpha, paper.mu, paper.beta, paper.reinit_every,
            paper.median_size) == (0.2, (0.2, 0.8, 0.1), 4.0, 0.4, 10, 7)
    assert paper.matching_cost == "ad" and paper.message_ambiguity == 0.0
    assert paper.patch_sizes == (3, 9, 18) and paper.max_iterations == 1500


def test_paper_takes_changes_and_validates_them():
    assert Params.paper(mu=3.0).mu == 3.0 and Params.paper(mu=3.0).refine is False
    with pytest.raises(ValueError, match=r"^params\.mu: expected a finite number >= 0"):
        Params.paper(mu=-1.0)
    with pytest.raises(ValueError, match=r"unknown parameter"):
        Params.paper(speed=2)


def test_appearance_resolves_by_the_start():
    from lss_kernels import Point
    from lss_kernels.params import APPEARANCE
    assert Params().appearance is None
    assert Params().for_start(Point(10.0, 12.0)).appearance == APPEARANCE
    assert Params().for_start((20.0, 20.0, 8.0, 6.0)).appearance == 0.0
    assert Params(appearance=0.0).for_start(Point(10.0, 12.0)).appearance == 0.0
    assert Params(appearance=0.5).for_start((20.0, 20.0, 8.0, 6.0)).appearance == 0.5
