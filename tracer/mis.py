"""MIS heuristics (Veach 1997, chapter 9).

In the multi-sample model each technique's pdf is scaled by its sample count before the
heuristic compares them: with n_l light samples and n_b BSDF samples, a light sample gets
w_l = h(n_l p_l, n_b p_b). In the one-sample model the counts become the probabilities of
choosing each technique. Delta samples are weighted 1 by the caller, because the other
technique has pdf 0 for them.
"""

from __future__ import annotations

import math

from .jit import jit
from .strategy import HEURISTICS

# Codes of HEURISTICS for compiled code. OPTIMAL weights as BALANCE does: optimal MIS is the
# balance heuristic plus a control variate (``tracer.tuning``), which the kernels add apart.
BALANCE, POWER, MAX, OPTIMAL = 0, 1, 2, 3
POWER_BETA = 2.0  # the power heuristic below squares: beta = 2 as in Veach's thesis


@jit
def weight_of(heuristic: int, mine: float, other: float) -> float:
    """The weight in [0, 1] of a sample whose own (count-scaled) pdf is ``mine`` when the other
    technique's is ``other`` (both >= 0); ``heuristic`` is a code BALANCE, POWER, MAX or OPTIMAL
    (which weights as BALANCE).

    Written through the ratio other/mine so that huge or infinite pdfs (near-specular lobes)
    give 1 or 0 instead of inf/inf = NaN; a sample with mine = 0 gets 0.
    """
    if not mine > 0.0:
        return 0.0
    ratio = other / mine
    if math.isnan(ratio):  # inf / inf: equal pdfs in the limit
        ratio = 1.0
    if heuristic == BALANCE or heuristic == OPTIMAL:
        return 1.0 / (1.0 + ratio)
    if heuristic == POWER:
        return 1.0 / (1.0 + ratio * ratio)
    # Maximum: ties go to neither side's advantage; split them so weights still sum to one.
    return 1.0 if ratio < 1.0 else (0.5 if ratio == 1.0 else 0.0)


def code(heuristic: str) -> int:
    """The code of a heuristic name."""
    if heuristic not in HEURISTICS:
        raise ValueError(f"unknown heuristic {heuristic!r}; expected one of {HEURISTICS}")
    return HEURISTICS.index(heuristic)
