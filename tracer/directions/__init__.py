"""Direction techniques: how a direction sample's direction is drawn, one module each.

Each module is a plug-in (``tracer.plugins.DirectionTechnique``) that defines (compiled, per
lane; templates where they call the material, ``tracer.kernels``):

- ``sample(kind, params, row, wo, u_lobe, u0, u1) -> (wi, weight, pdf, delta)``: a direction
  ``wi`` (local to the shading frame) for the material ``row`` of code ``kind`` seen from
  ``wo``; ``weight`` = f |cos theta_i| / pdf as RGB (a delta lobe's: its contribution over its
  choice probability), ``pdf`` in solid angle (0 for a delta lobe), ``delta`` for a delta lobe;
- ``pdf(wi, pdf_material) -> float``: the pdf with which ``sample`` picks ``wi``, given the
  material's own pdf of it (the ``bsdf`` technique's answer; the others ignore it).

==========  ==================================================  =============================
technique   direction                                            module
==========  ==================================================  =============================
uniform     uniform over the hemisphere, 1 / 2 pi                ``uniform.py``
cosine      cosine-weighted over the hemisphere, cos / pi        ``cosine.py``
bsdf        the material's own sampling                          ``bsdf.py``
==========  ==================================================  =============================
"""
