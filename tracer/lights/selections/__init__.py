"""Light selections: which emitter candidate a light sample samples, one module each.

Each module is a plug-in (``tracer.plugins.LightSelection``, pbrt-v4's two-method
``LightSampler``) that defines:

- ``tables(candidates) -> NamedTuple``: what it reads, from the render's candidates
  (``tracer.lights.emitters.Candidates``: flux, owner, area, bounds), with a field ``pmf`` (K,)
  of each candidate's probability by power (what ``LightSampler.pmf`` reports);
- ``choose(tables, x, n_receiver, u) -> (k, pmf)`` (compiled): a candidate for the shading point
  ``x`` with shading normal ``n_receiver`` from one uniform ``u``, and its probability;
  ``(-1, 0.0)`` if none can light ``x``;
- ``pmf(tables, k, x, n_receiver) -> float`` (compiled): the probability that ``choose`` picks
  ``k`` at ``x``, computed as ``choose`` computes it, so that MIS weighs a BSDF sample that hits
  a light with the very probability the light technique would have chosen it;
- optionally ``runs_as(tables) -> str | None``: the name of a cheaper selection whose choices
  have the same probabilities as this one's at every point, for these tables (a light BVH of
  one leaf and no lights at infinity picks its members by power, as ``power`` does), or None. ``tracer.lights.build_tables`` then
  builds and runs that one, and the render record says so (``light_selection_ran``).

==========  ==============================================================================
selection   module
==========  ==============================================================================
power       ``power.py``: in proportion to flux, Walker's alias table (``lights.selection``)
uniform     ``uniform.py``: each light alike, then its triangles by area
bvh         ``bvh.py``: a light BVH's importance at the point (``lights.bvh``)
==========  ==============================================================================
"""
