"""When a solid-angle technique steps aside for area sampling: a light small for its distance.

Sampling a planar light uniformly by area, the estimator carries the factor
cos theta_light / d^2 = h / d^3 (h the distance from x to the light's plane, the same for
every point of the light), which solid-angle sampling removes. Over a light of radius r (its
points within r of its centre c), d = |y - x| varies by at most 2 r around |c - x|, so that
factor's relative variation is of order r / |c - x|, and the variance it adds to area sampling
of order (r / |c - x|)^2: with a square light of half-diagonal r beside x (offset as far as
it is high) it measured 0.7 (r / |c - x|)^2, straight above x 0.002-0.07 (r / |c - x|)^2
(the first order cancels). Solid-angle sampling pays a spherical polygon's trigonometry and a
square root or two for each sample and each pdf (nearly as much as a whole light-sampled
camera sample on a Cornell box here); where the variance it removes is a few per cent of
that, area sampling wins at equal time (issue 34: `solid-angle-cos` measured 0.86x area on a
Cornell box's small ceiling light).

So :func:`far` is the test every solid-angle technique makes first, from x and the light
alone, the same in ``sample`` and ``pdf`` (the pair stays consistent, as with pbrt-v4's
solid-angle threshold, which the techniques keep for what passes this one):
(r / |c - x|)^2 < ``FAR``. Its cost is a few multiplications, against the spherical
polygon's solid angle that pbrt-v4's test computes first.

``FAR`` was measured (``benchmarks/far_light.py``, docs/results/light-sampling.md: 128 x 128,
equal time, 3 seeds) on tracer's Cornell box, Mitsuba's own (held out) and a room of 18 lights
generated from a seed not looked at before: with 0 (never), ``mis`` with ``solid-angle`` lost
to ``area`` on the room (0.77x) and Mitsuba's box (0.95x); with 0.03, 0.95x and 0.93x, and
``light`` on the room went from 1.18x to 1.60x. 0.1 measured about the same at equal time,
but raises the per-sample relMSE more where solid-angle sampling helped (tracer's Cornell box,
``solid-angle``: 0.0011 at 0, 0.00113 at 0.03, 0.00147 at 0.1, area sampling's 0.00144); by the
estimate above it leaves at most about 2% of relative variance (0.7 x 0.03) to area sampling's
geometry factor.
"""

from __future__ import annotations

from ..frame import dot, sub
from ..jit import jit

# (radius / distance)^2 below which a solid-angle technique samples by area instead.
FAR = 0.03


@jit
def far(x, centre, radius2: float) -> bool:
    """Whether a light whose points lie within ``sqrt(radius2)`` of ``centre`` is small enough,
    seen from ``x``, to be sampled by area (module docstring)."""
    v = sub(centre, x)
    return radius2 < FAR * dot(v, v)
