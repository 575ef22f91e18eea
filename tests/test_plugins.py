"""One small plug-in of each kind (``tests/plugins/``), each one module that registers itself, used
by renders without any other edit: a material (``lambert_uniform``), a light technique
(``triangle_area_sqrt``, light sampling ``area-sqrt``), a light selection (``index``) and a
sampler (``pcg``). They are checked as the built-ins are, against the closed form of
test_estimators (a diffuse plane under three polygonal lights).

They run in a child process: registering a plug-in changes the registries for the rest of a
process (and so, in a suite, what other tests see), as it would in a user's program.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
from test_estimators import ANALYTIC_SCENE, POINTS, expected_radiance, shoot_at

from stats import sidak, t_test_mean

TESTS = Path(__file__).resolve().parent
PLUGINS = ("plugins.lambert_uniform", "plugins.triangle_area_sqrt", "plugins.index_selection",
           "plugins.pcg_sampler")

# Each strategy uses all four plug-ins at once, so that each plug-in's sample and pdf are used:
# light samples alone (the technique, the selection), direction samples alone (the material's
# sample), and both combined by MIS (every pdf of both sides, which the weights must reproduce).
STRATEGIES = {
    "light": dict(name="light"),
    "bsdf": dict(name="bsdf"),
    "mis": dict(name="mis", heuristic="power"),
    "mis_one_sample": dict(name="mis", heuristic="balance", one_sample=True),
}
SAMPLES = 40_000

CHILD = textwrap.dedent("""
    import importlib, json, sys
    import numpy as np
    from tracer import plugins
    from tracer.estimator import DirectLighting
    from tracer.scene import load_scene
    from tracer.strategy import Strategy

    scene_path, out, modules, strategies = sys.argv[1], sys.argv[2], json.loads(sys.argv[3]), json.loads(sys.argv[4])
    for module in modules:
        importlib.import_module(module)
    found = {kind: plugins.names(kind) for kind in ("material", "light_technique", "light_selection", "sampler")}
    scene = load_scene(scene_path)
    rays = np.load(out + ".rays.npz")
    arrays, described = {}, {}
    for i, (slug, options) in enumerate(sorted(strategies.items())):
        strategy = Strategy(**options, light_sampling="area-sqrt", light_selection="index")
        estimator = DirectLighting(scene, strategy)
        arrays[slug] = estimator.radiance(rays["origins"], rays["dirs"], seed=500 + i, sampler="pcg")
        described[slug] = estimator.features("pcg").describe()
    np.savez(out, **arrays)
    print(json.dumps({"found": found, "described": described}))
""")


def test_each_kind_of_plugin_is_one_module_that_renders_the_closed_form(write_scene, tmp_path):
    """The plug-ins registered themselves (the registries list them), each build says it holds
    them, and each strategy's mean radiance at the four points matches rho/pi * E: one-sample
    t-tests of 40,000 samples per strategy x point x channel, Sidak-corrected over all of them at
    the suite's 1% family level (the channels of one point share their samples, and Sidak stays
    conservative for such positively dependent tests). A plug-in whose pdf does not match its
    sampling, a selection pmf that is not its choice's, or a sampler whose numbers are not
    uniform shifts a mean by many standard errors (test_estimators' argument)."""
    scene = write_scene(ANALYTIC_SCENE.replace('type = "diffuse"', 'type = "lambert_uniform"'))
    origins, dirs, which = shoot_at(POINTS, SAMPLES)
    out = tmp_path / "radiance"
    np.savez(str(out) + ".rays.npz", origins=origins, dirs=dirs)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")]),
               TRACER_KERNELS="scene")
    done = subprocess.run([sys.executable, "-c", CHILD, str(scene), str(out), json.dumps(PLUGINS),
                           json.dumps(STRATEGIES)], capture_output=True, text=True, env=env, timeout=1800)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert "lambert_uniform" in report["found"]["material"]
    assert "triangle_area_sqrt" in report["found"]["light_technique"]
    assert "index" in report["found"]["light_selection"]
    assert "pcg" in report["found"]["sampler"]
    for slug, line in report["described"].items():
        assert "lambert_uniform" in line and "triangle_area_sqrt" in line, (slug, line)
        assert "index selection" in line and "pcg sampler" in line, (slug, line)
        assert "diffuse" not in line.split(";")[0], (slug, line)  # the plane's type only
    radiance = np.load(str(out) + ".npz")
    expected = np.array([expected_radiance(x) for x in POINTS])
    level = sidak(len(STRATEGIES) * len(POINTS) * 3)
    failures = []
    for slug in STRATEGIES:
        values = radiance[slug]
        assert values.shape == (len(origins), 3) and np.all(np.isfinite(values)), slug
        for p in range(len(POINTS)):
            pvalues = t_test_mean(values[which == p], expected[p])
            if np.any(pvalues < level):
                failures.append(f"{slug}: point {POINTS[p]} mean {values[which == p].mean(axis=0)} "
                                f"expected {expected[p]} p={pvalues}")
    assert not failures, "\n".join(failures)
