"""MIS heuristics (Veach 1997, chapter 9).

In the multi-sample model each technique's pdf is scaled by its sample count before the
heuristic compares them: with n_l light samples and n_b BSDF samples, a light sample gets
w_l = h(n_l p_l, n_b p_b). In the one-sample model the counts become the probabilities of
choosing each technique. Delta samples are weighted 1 by the caller, because the other
technique has pdf 0 for them.
"""

from __future__ import annotations

import numpy as np

HEURISTICS = ("balance", "power", "max")
POWER_BETA = 2.0


def weight(heuristic: str, mine: np.ndarray, other: np.ndarray) -> np.ndarray:
    """The weight of a sample whose own (count-scaled) pdf is ``mine`` when the other
    technique's is ``other``; both ``(n,)``, >= 0. Returns ``(n,)`` in [0, 1].

    Written through the ratio other/mine so that huge or infinite pdfs (near-specular lobes)
    give 1 or 0 instead of inf/inf = NaN; a sample with mine = 0 gets 0.
    """
    positive = mine > 0.0
    ratio = np.where(positive, other / np.where(positive, mine, 1.0), np.inf)
    ratio = np.nan_to_num(ratio, nan=1.0)  # inf / inf: equal pdfs in the limit
    if heuristic == "balance":
        w = 1.0 / (1.0 + ratio)
    elif heuristic == "power":
        w = 1.0 / (1.0 + ratio**POWER_BETA)
    elif heuristic == "max":
        # Ties go to neither side's advantage: split them so weights still sum to one.
        w = np.where(ratio < 1.0, 1.0, np.where(ratio == 1.0, 0.5, 0.0))
    else:
        raise ValueError(f"unknown heuristic {heuristic!r}; expected one of {HEURISTICS}")
    return np.where(positive, w, 0.0)
