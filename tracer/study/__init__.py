"""Study tools: code that measures the renderer rather than being it.

The renderer core (``tracer.scene``, ``tracer.estimator``, ``tracer.render_loop``, ``tracer.film``,
...) computes images; the modules here run it and judge what comes out:

- ``metrics``: noise and error measures (MSE, relMSE, variance, efficiency, ratio maps);
- ``statistics``: Sidak levels and the image-mean z-test shared by the checks and the tests;
- ``compare`` and ``report``: equal-spp / equal-time strategy comparisons and their web page;
- ``check``: the noise and bias regression test against a committed baseline;
- ``stability``: every strategy on the scenes in ``cases/`` where some strategy is known to fail;
- ``primer``: Monte Carlo exercises on 1-D and 2-D integrals, independent of the renderer.

Imports point one way: study tools use the core, and the core never imports them (only the
command line, ``tracer.cli``, reaches in here, to run them).
"""
