"""Light techniques: how a direction toward one emitter candidate is drawn, one module each.

Each module is a plug-in (``tracer.plugins.LightTechnique``) that says which emitter kinds it
samples (``tracer.lights.emitters``: ``triangle``, ``textured_triangle``, ``rectangle``,
``sphere``, ``point``, ``directional``) and
for which ``--light-sampling`` values, and defines (compiled, per lane):

- ``rows(emitters) -> (K, width) float32``: its table row for each emitter of the kinds it takes
  (named columns: a row is one 64-byte cache line, which light sampling reads at random);
- ``sample(rows, k, x, n, u0, u1) -> (wi, dist, le, pdf, delta)``: a direction from shading
  point ``x`` (geometric normal ``n``, toward the viewer) toward candidate ``k``: ``wi`` world
  unit, ``dist`` the distance to the sampled point, ``le`` the radiance arriving along ``wi``
  (a delta light: I / d^2), ``pdf`` in solid angle without the selection probability (a delta
  light: 1), 0 where the sample is invalid; ``delta`` for a delta light's sample;
- ``pdf(rows, k, x, n, wi, dist) -> float``: the pdf with which ``sample`` picks ``wi`` from
  ``x`` when that direction hits candidate ``k`` at distance ``dist`` (a pure function of
  them, as MIS needs; 0 for a delta light and from the back side).

==========================  ====  =========  ==================  ===================================
technique                   code  emitters   light sampling      module
==========================  ====  =========  ==================  ===================================
triangle_area               0     triangle   area                ``triangle_area.py``
point                       1     point      every one           ``point.py``
sphere_area                 2     sphere     area                ``sphere_area.py``
sphere_cone                 3     sphere     solid-angle[-cos]   ``sphere_cone.py``
spherical_triangle          4     triangle   solid-angle         ``spherical_triangle.py``
spherical_triangle_cos      5     triangle   solid-angle-cos     ``spherical_triangle_cos.py``
spherical_rectangle         6     rectangle  solid-angle         ``spherical_rectangle.py``
spherical_rectangle_cos     7     rectangle  solid-angle-cos     ``spherical_rectangle_cos.py``
directional                 8     direc-     every one           ``directional.py``
                                  tional
triangle_texels             9     textured_  area                ``triangle_texels.py``
                                  triangle
==========================  ====  =========  ==================  ===================================

Adding a technique: one module here (found by ``plugins.discover``); a new ``--light-sampling``
value is any name a technique lists. A technique that samples a shape exactly needs the
renderer to intersect that same shape (``tracer.geometry``), else MIS converges to neither.
"""
