"""Command line: argument parsing and calls into the library, no math.

Exit status: 0 done, 1 a check failed, 2 bad input (one line on stderr, no traceback),
130 interrupted by Ctrl-C (after writing what was rendered).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import sys
from pathlib import Path

from . import __version__, interrupts, notices
from .errors import InputError
from .plugins import Names
from .sampler_choice import DEFAULT_SAMPLER
from .strategy import MAX_SAMPLES_PER_CAMERA_SAMPLE


def _sampler_names():
    from .sampler_choice import SAMPLERS

    return SAMPLERS


# The plug-ins' names, read from their registries only when an option is checked or help printed
# (``plugins.Names``): building the parser imports no plug-in and no numba.
SAMPLERS = Names(_sampler_names)

# Every command that takes a scene resolves it with tracer.scene.resolve_scene.
SCENE_HELP = "scene file, or the name of a scene shipped with tracer (tracer scenes lists them)"

EXIT_CHECK_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130


def _int_in(lo: int, hi: int):
    """An argparse type: a whole number in lo .. hi, with a message that says what was wrong."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got '{text[:40]}'") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"expected a whole number in {lo} .. {hi}, got {text[:40]}")
        return value

    return parse


# Bounds that mean something: sample indices and counts stay exact below 2^53
# (tracer.record.MAX_SAMPLE_INDEX), seeds are 64-bit, each thread keeps two batches in flight,
# and a camera sample's shading rays are sized to fit in memory.
MAX_SPP = 2**53
_spp = _int_in(1, MAX_SPP)
_seed = _int_in(0, 2**64 - 1)
_threads = _int_in(1, 1024)
_workers = _int_in(1, 1024)
_samples_per_camera_sample = _int_in(0, MAX_SAMPLES_PER_CAMERA_SAMPLE)
_ris_candidates = _int_in(1, MAX_SAMPLES_PER_CAMERA_SAMPLE)


def _counts(text: str) -> list[int]:
    """An argparse type: a comma-separated list of distinct ris candidate counts."""
    values = [_ris_candidates(part.strip()) for part in text.split(",") if part.strip()]
    if not values or len(set(values)) != len(values):
        raise argparse.ArgumentTypeError("expected distinct whole numbers >= 1, comma-separated, "
                                         f"got '{text[:40]}'")
    return values
_side = _int_in(1, 2**31 - 1)


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got '{text}'") from None
    if not value > 0.0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text}")
    return value


def _crop(text: str) -> tuple[int, int, int, int]:
    parts = text.split(",")
    try:
        x, y, w, h = (int(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y,W,H (4 whole numbers), got '{text}'") from None
    if x < 0 or y < 0 or w < 1 or h < 1:
        raise argparse.ArgumentTypeError(f"expected X,Y >= 0 and W,H >= 1, got '{text}'")
    return x, y, w, h


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: what is wrong and where to look, not the whole usage
    (which --help prints). Subcommand parsers are made of this class too."""

    def error(self, message: str):
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    from .strategy import CLASSIC_STRATEGIES, STRATEGIES

    parser = _Parser(
        prog="tracer", description="Direct-lighting path tracer for comparing sampling strategies.")
    parser.add_argument("--version", action="version", version=f"tracer {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    r = sub.add_parser("render", help="render a scene file to EXR (with variance) and PNG",
                       description="Render a scene to an EXR with per-pixel variance and a PNG preview.")
    r.add_argument("scene", nargs="?", help="scene file, or the name of a scene shipped with tracer (tracer "
                   "scenes lists them; default: veach_mis)")
    r.add_argument("-o", "--output", help="output EXR path (default: SCENE_STRATEGY.exr here); "
                   "the PNG preview goes beside it")
    r.add_argument("--force", action="store_true", help="replace an existing OUTPUT and its PNG preview "
                   "(without it, a render never writes over an existing file)")
    r.add_argument("--spp", type=_spp, help="samples per pixel (default: the scene's, else 64)")
    r.add_argument("--strategy", choices=STRATEGIES,
                   help="sampling strategy (default: the scene's, else mis)")
    _add_strategy_options(r)
    _add_sampler_option(r)
    _add_render_options(r)
    r.set_defaults(run=cmd_render)

    ref = sub.add_parser("reference", help="render or grow a high-spp MIS reference",
                         description="Render a high-spp MIS reference (half-float EXR), or add samples "
                         "to an existing one with --resume.")
    ref.add_argument("scene", help=SCENE_HELP)
    ref.add_argument("-o", "--output", help="reference EXR (default: SCENE_reference.exr here)")
    ref.add_argument("--spp", type=_spp, default=1024,
                     help="samples per pixel to add (default 1024)")
    ref.add_argument("--resume", action="store_true",
                     help="add --spp samples to the existing OUTPUT (fresh random numbers; spp adds up)")
    ref.add_argument("--float", action="store_true", help="store 32-bit floats instead of half")
    ref.add_argument("--force", action="store_true", help="replace an existing OUTPUT (without it, "
                     "an existing reference is only ever grown, with --resume)")
    _add_strategy_options(ref)
    _add_sampler_option(ref, resumed=True)
    _add_render_options(ref)
    _add_cluster_options(ref, tasks="the sample range is cut into tasks of disjoint sample indices, pooled "
                         "in a fixed order: the same image, bit for bit, as without", task_spp=True)
    # None = not given: a resume takes these from the file, a new reference the usual defaults.
    ref.set_defaults(run=cmd_reference, heuristic=None, light_samples=None, bsdf_samples=None,
                     one_sample=None, light_selection=None, light_sampling=None, allocation=None)

    c = sub.add_parser("compare", help="compare strategies against a reference: images, maps, charts",
                       description="Render several strategies at equal spp or equal time and compare them "
                       "with a reference: EXR/PNG per strategy, error and FLIP maps, a labelled grid, "
                       "efficiency-ratio maps, metrics.json/csv and index.html, whose interactive viewer "
                       "(it opens from disk) flips, zooms and reads out the float images.")
    c.add_argument("scene", help=SCENE_HELP)
    c.add_argument("--reference", required=True,
                   help="reference EXR: tracer reference's, or another renderer's (channels R, G, B, or a "
                   "gray Y; variance.R/G/B if present, read as one sample's variance, as tracer writes it)")
    c.add_argument("--reference-layer", metavar="NAME",
                   help="another renderer's EXR: compare with layer NAME (channels NAME.R, NAME.G, NAME.B, "
                   "variance NAME.variance.R/G/B); default the plain R, G, B, else the file's one RGB layer")
    c.add_argument("--reference-spp", type=_int_in(2, MAX_SPP), metavar="N",
                   help="another renderer's EXR: samples per pixel it holds, by which its variance channels "
                   "are divided to subtract its noise from the errors (without it nothing is subtracted, "
                   "and compare says so); a tracer reference's own count is in its header")
    c.add_argument("--strategies", default=",".join(CLASSIC_STRATEGIES),
                   help=f"comma-separated strategies, some of {', '.join(STRATEGIES)} (default: all but ris)")
    budget = c.add_mutually_exclusive_group(required=True)
    budget.add_argument("--spp", type=_spp, help="equal samples: every strategy renders N spp")
    budget.add_argument("--time", type=_positive_float, metavar="SECONDS",
                        help="equal time: every strategy renders for SECONDS of wall-clock time "
                        "(elapsed, as a user waits; --clock cpu for CPU time)")
    c.add_argument("--out", default="compare", help="output folder (default ./compare)")
    c.add_argument("--sweep", action="store_true",
                   help="also: relMSE at spp 1, 2, 4, ... averaged over --sweep-seeds seeds (charts "
                   "with fitted slopes and their 95%% intervals) and the MIS light:BSDF allocation sweep")
    c.add_argument("--sweep-seeds", type=_int_in(2, 1000), default=8, metavar="N",
                   help="independent seeds per sweep point, none of which the reference holds (default 8)")
    c.add_argument("--target", type=_positive_float, default=0.01,
                   help="relMSE whose time to reach --sweep reports, with its interval, where the sweep "
                   "supports it (default 0.01)")
    c.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                   help="what render time is: wall (default: elapsed wall-clock time of each render) or "
                   "cpu (process CPU time of each render summed over its threads: up to --threads times "
                   "the wall time; on a shared machine other processes inflate it far less); --time, "
                   "efficiency and the sweep's times use it")
    c.add_argument("--figure-format", action="append", metavar="FMT",
                   help="also write the charts and maps as FMT: pdf or svg (vector; repeatable or "
                   "comma-separated; PNG at 300 dpi is always written)")
    c.add_argument("--crop", action="append", type=_crop, metavar="X,Y,W,H",
                   help="inset region in pixels (repeatable; default: chosen where strategies differ most)")
    _add_strategy_options(c, compared=True)
    _add_sampler_option(c, compared=True)
    c.add_argument("--seed", type=_seed, default=None,
                   help="random seed (default: the smallest the reference holds no samples of)")
    c.add_argument("--threads", type=_threads, default=os.cpu_count() or 1, help="worker threads")
    c.add_argument("--exposure", type=_exposure, default=0.0,
                   help="exposure in stops of the PNGs, and the viewer's at first (default 0)")
    c.add_argument("--quiet", action="store_true", help="no progress lines")
    _add_cluster_options(c, tasks="each strategy (and each seed of a sweep) renders as a task on one thread "
                         "of a worker, timed there")
    c.set_defaults(run=cmd_compare)

    ch = sub.add_parser("check", help="regression-test noise levels and bias against a baseline",
                        description="Render every baseline entry with its seeds and test that noise did not "
                        "grow (one-sided exact Mann-Whitney U tests of per-seed relMSE and variance), "
                        "that the image mean did not move (a permutation test of the renders' image means "
                        "against the baseline's) and that the image matches the reference (per-pixel "
                        "z-tests), at a 1% false-alarm rate for the whole file. --create makes a baseline "
                        "for your own scenes; --update re-measures one, tests its image mean against the "
                        "reference (t-test) and refuses entries too heavy-tailed for that, naming the spp "
                        "they need.")
    ch.add_argument("--baseline", default=None,
                    help="baseline JSON (default: ./tracer_baseline.json if present, else the shipped "
                    "scenes' renders/noise_baseline.json of the source checkout tracer runs from, or else of "
                    "the one the current folder is in; the command says which it used)")
    ch.add_argument("--update", action="store_true",
                    help="re-measure the baseline's entries and rewrite it (refuses entries too heavy-tailed "
                    "to test)")
    ch.add_argument("--create", metavar="BASELINE",
                    help="write a new baseline for --scenes x --strategies, rendering MIS references into "
                    "references/ beside it")
    ch.add_argument("--scenes", metavar="A.toml,B.toml",
                    help="with --create: comma-separated scene files or shipped scene names (tracer scenes "
                    "lists them)")
    ch.add_argument("--strategies", metavar="LIST",
                    help="with --create: comma-separated strategies (uniform, cosine, bsdf, light, mis, "
                    "mis-balance, mis-power, mis-max)")
    ch.add_argument("--spp", type=_int_in(1, 2**31), default=None,
                    help="with --create: samples per pixel of each seed's render (default 16)")
    ch.add_argument("--seeds", type=_int_in(2, 64), default=None,
                    help="with --create: renders (seeds 1..N) per entry (default 8)")
    ch.add_argument("--reference-spp", type=_int_in(2, 2**31), default=None,
                    help="with --create: MIS samples per pixel of each reference (default 1024)")
    ch.add_argument("--size", type=_int_in(4, 4096), default=None,
                    help="with --create: longer side of the check's images and references in pixels "
                    "(default 64)")
    ch.add_argument("--sampler", choices=SAMPLERS, default=None, metavar="NAME",
                    help=f"with --create: the sampler of every entry, one of %(choices)s "
                    f"(default {DEFAULT_SAMPLER})")
    ch.add_argument("--out", default="check_failures", help="where the maps of failing entries go, a "
                    "folder per entry named SCENE_STRATEGY (default check_failures)")
    ch.add_argument("--seed-offset", type=_seed, default=0,
                    help="add this to every seed (other random numbers, same statistics)")
    ch.add_argument("--threads", type=_threads, default=os.cpu_count() or 1, help="worker threads")
    _add_cluster_options(ch, tasks="every render of an entry and seed is a task (each on one thread); "
                         "the references of --create render here")
    ch.set_defaults(run=cmd_check)

    pr = sub.add_parser("primer", help="Monte Carlo primer: five exercises, each a table and a figure",
                        description="Run the Monte Carlo primer (inversion method, rejection sampling, "
                        "importance sampling, MIS, quasi-Monte Carlo): print a table per exercise, each "
                        "measured value with its standard error against the exact value, and with --out "
                        "write one PNG figure per exercise.")
    pr.add_argument("--out", metavar="DIR",
                    help="folder for the five PNG figures (created if missing; default: tables only)")
    pr.add_argument("--seed", type=_seed, default=0, help="random seed (default 0)")
    pr.set_defaults(run=cmd_primer)

    st = sub.add_parser(
        "stability",
        help="every strategy on every known failure case: table, JSON, heat map",
        description="Run every strategy on the cases where sampling strategies fail (tiny, big, grazing "
        "and hidden lights, point lights, mirrors, GGX alpha 1e-4, zero-area triangles, scaled scenes, "
        "sample counts) and check what must hold; exit 1 if anything does not.",
    )
    st.add_argument("--out", default="stability", help="folder for stability.json and stability.png")
    st.add_argument("--spp", type=_spp, default=64, help="samples per pixel per strategy (default 64)")
    st.add_argument("--reference-spp", type=_spp, default=1024,
                    help="spp of each case's MIS reference (default 1024)")
    st.add_argument("--seed", type=_seed, default=0, help="random seed (default 0)")
    _add_sampler_option(st, default=DEFAULT_SAMPLER)
    st.add_argument("--threads", type=_threads, default=os.cpu_count() or 1, help="worker threads")
    st.set_defaults(run=cmd_stability)

    m = sub.add_parser("merge", help="merge two renders of the same scene and strategy exactly",
                       description="Pool the samples of two renders (per-pixel count, mean and variance).")
    m.add_argument("a", help="first EXR")
    m.add_argument("b", help="second EXR")
    m.add_argument("-o", "--output", required=True, help="merged EXR (PNG preview beside it)")
    m.add_argument("--exposure", type=_exposure, default=0.0,
                   help="PNG preview exposure in stops (default 0)")
    m.add_argument("--quiet", action="store_true", help="no summary line")
    m.set_defaults(run=cmd_merge)

    cv = sub.add_parser("convert", help="write a scene (Mitsuba 3 XML or TOML) as a tracer TOML scene",
                        description="Read a scene (a Mitsuba 3 XML file, docs/MITSUBA_XML.md, or a TOML one) "
                        "and write the TOML scene that renders the same (the same scene digest, checked by "
                        "reading it back), with every mesh, Mitsuba cube and disk as a PLY file beside it "
                        "(STEM_shapeN.ply).")
    cv.add_argument("scene", help="scene file (.xml: Mitsuba 3; anything else: TOML), or the name of a "
                    "scene shipped with tracer (tracer scenes lists them)")
    cv.add_argument("-o", "--output", help="TOML file to write (default: SCENE.toml here)")
    cv.add_argument("--width", type=_side, help="film width to convert at (a Mitsuba scene's field of view "
                    "follows its fov_axis; the TOML holds the vertical angle at this size)")
    cv.add_argument("--height", type=_side, help="film height to convert at")
    _add_define_option(cv)
    cv.add_argument("--quiet", action="store_true", help="no summary line")
    cv.set_defaults(run=cmd_convert)

    sc = sub.add_parser("scenes", help="list the scenes shipped with tracer, by name",
                        description="List the scenes shipped with tracer, one line each: the name that "
                        "every command taking a scene accepts (tracer render cornell) and what the scene "
                        "shows. A file of that name in the current folder is used before a shipped scene.")
    sc.add_argument("--paths", action="store_true", help="also print each scene's file (to copy and edit)")
    sc.set_defaults(run=cmd_scenes)
    return parser


def _add_strategy_options(p: argparse.ArgumentParser, compared: bool = False) -> None:
    """The estimator's options; with ``compared``, ``--light-sampling`` takes a list."""
    from .strategy import (
        ALLOCATIONS,
        DEFAULT_LIGHT_SAMPLING,
        DEFAULT_RIS_CANDIDATES,
        ENVIRONMENT_SAMPLING_DOCS,
        ENVIRONMENT_SAMPLINGS,
        HEURISTICS,
        RIS_SOURCES,
        light_samplings,
        light_selections,
    )

    LIGHT_SAMPLINGS, LIGHT_SELECTIONS = Names(light_samplings), Names(light_selections)

    heuristics = "balance, power, max, or optimal (balance plus a control variate learned per pixel from " \
        "earlier passes)"
    allocations = "fixed (N light + M bsdf) or adaptive (mis: each pixel splits N + M samples as earlier " \
        "passes say is best)"
    if compared:
        p.add_argument("--heuristic", type=_names_of(HEURISTICS), default=["power"], metavar="LIST",
                       help=f"comma-separated MIS heuristics to compare, each a mis run: some of "
                       f"{heuristics} "
                       "(default power; ris uses the first of balance, power, max given)")
        p.add_argument("--allocation", type=_names_of(ALLOCATIONS), default=["fixed"], metavar="LIST",
                       help=f"comma-separated sample allocations of mis to compare: {allocations} "
                       "(default fixed)")
    else:
        p.add_argument("--heuristic", choices=HEURISTICS, default="power",
                       help=f"MIS heuristic: {heuristics}; default power (also weights ris's candidates of "
                       "two techniques)")
        p.add_argument("--allocation", choices=ALLOCATIONS, default="fixed",
                       help=f"how mis splits its samples: {allocations}; default fixed")
    p.add_argument("--light-samples", type=_samples_per_camera_sample, default=1, metavar="N",
                   help="light samples per camera sample (light, mis; default 1)")
    p.add_argument("--bsdf-samples", type=_samples_per_camera_sample, default=1, metavar="M",
                   help="direction samples per camera sample (uniform, cosine, bsdf, mis; default 1)")
    p.add_argument("--one-sample", action="store_true",
                   help="one-sample MIS: each camera sample picks light or BSDF with probability N:M")
    selections = "power (in proportion to power), uniform, or bvh (a light BVH: by an importance bound at " \
        "the shading point)"
    ris_sources = "light (light samples) or light+bsdf (half of them BSDF samples, MIS-weighted)"
    if compared:
        p.add_argument("--light-selection", type=_names_of(LIGHT_SELECTIONS), default=["power"],
                       metavar="LIST",
                       help=f"comma-separated light selections to compare, each with every strategy that "
                       f"takes light samples: some of {selections} (default power)")
        p.add_argument("--ris-candidates", type=_counts, default=[DEFAULT_RIS_CANDIDATES],
                       metavar="LIST",
                       help=f"comma-separated candidate counts M of the ris strategy, one run each "
                       f"(default {DEFAULT_RIS_CANDIDATES})")
        p.add_argument("--ris-sources", type=_names_of(RIS_SOURCES), default=[RIS_SOURCES[0]],
                       metavar="LIST",
                       help=f"comma-separated sources of ris's candidates: some of {ris_sources} "
                       "(default light)")
    else:
        p.add_argument("--light-selection", choices=LIGHT_SELECTIONS, default="power", metavar="NAME",
                       help=f"how to pick the light to sample, one of %(choices)s: {selections}; "
                       "default power")
        p.add_argument("--ris-candidates", type=_ris_candidates, default=DEFAULT_RIS_CANDIDATES,
                       metavar="M",
                       help=f"ris: candidates per camera sample (default {DEFAULT_RIS_CANDIDATES})")
        p.add_argument("--ris-sources", choices=RIS_SOURCES, default=RIS_SOURCES[0],
                       help=f"ris: where candidates come from: {ris_sources}; default light")
    environments = "; ".join(f"{name}: {doc}" for name, doc in ENVIRONMENT_SAMPLING_DOCS.items())
    if compared:
        p.add_argument("--environment-sampling", type=_names_of(ENVIRONMENT_SAMPLINGS), default=None,
                       metavar="LIST",
                       help="comma-separated environment samplings to compare, each with every strategy "
                       f"that takes light samples and can take it ({environments}; default luminance)")
    else:
        p.add_argument("--environment-sampling", choices=ENVIRONMENT_SAMPLINGS, default=None, metavar="NAME",
                       help=f"how light sampling draws a direction of the environment: {environments} "
                       "(default luminance)")
    if compared:
        listed = p.add_argument("--light-sampling", type=_names_of(LIGHT_SAMPLINGS), default=None,
                                metavar="LIST",
                                help="comma-separated light-sampling techniques to compare, each with every "
                                "strategy that takes light samples: some of %(names)s "
                                "(default: the scene's [render] light_sampling, "
                                f"else {DEFAULT_LIGHT_SAMPLING})")
        listed.names = LIGHT_SAMPLINGS  # read by the help text's %(names)s when help is printed
        return
    p.add_argument("--light-sampling", choices=LIGHT_SAMPLINGS, default=None, metavar="NAME",
                   help="how to sample the chosen light, one of %(choices)s: by area, by the solid angle "
                   "it subtends, or by "
                   "solid angle warped toward the receiver's cosine (default: the scene's [render] "
                   f"light_sampling, else {DEFAULT_LIGHT_SAMPLING})")


def _add_sampler_option(p: argparse.ArgumentParser, compared: bool = False, default: str | None = None,
                        resumed: bool = False) -> None:
    """``--sampler``: one name, or with ``compared`` a comma-separated list."""
    what = ("%(names)s (independent: a counter-based hash; stratified: jittered strata; sobol: "
            "Owen-scrambled Sobol points); the variance stays honest for each (8 independent replicates)")
    if compared:
        listed = p.add_argument("--sampler", type=_names_of(SAMPLERS), default=None, metavar="LIST",
                                help=f"comma-separated samplers to compare, each with every strategy: "
                                f"some of "
                                f"{what} (default: the scene's [render] sampler, else {DEFAULT_SAMPLER})")
        listed.names = SAMPLERS  # read by the help text's %(names)s when help is printed
        return
    fallback = f"default {default}" if default else \
        f"default: the scene's [render] sampler, else {DEFAULT_SAMPLER}"
    kept = "; --resume keeps the file's" if resumed else ""
    single = p.add_argument("--sampler", choices=SAMPLERS, default=default, metavar="NAME",
                            help=f"where the random numbers come from, one of {what} ({fallback}{kept})")
    single.names = SAMPLERS


def _names_of(choices: tuple[str, ...]):
    """An argparse type: a comma-separated list of distinct names from ``choices``."""
    def parse(text: str) -> list[str]:
        names = [n.strip() for n in text.split(",") if n.strip()]
        bad = [n for n in names if n not in choices]
        if bad or not names or len(set(names)) != len(names):
            what = f"unknown '{bad[0]}'" if bad else ("repeated names" if names else "empty")
            raise argparse.ArgumentTypeError(f"{what} (expected some of {', '.join(choices)})")
        return names
    return parse


_PARAMETER = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)=(.*)", re.S)


def _define(text: str) -> tuple[str, str]:
    """``NAME=VALUE`` of ``-D``: a Mitsuba scene parameter."""
    found = _PARAMETER.fullmatch(text)
    if found is None or "\n" in text:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE (a scene's $NAME), got {text[:60]!r}")
    return found.group(1), found.group(2)


def _add_define_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("-D", "--define", type=_define, action="append", default=[], metavar="NAME=VALUE",
                   help="set a Mitsuba scene's $NAME, as Mitsuba's -D does (over its <default>; repeatable)")


def _parameters(args: argparse.Namespace) -> dict[str, str]:
    return dict(getattr(args, "define", []) or [])


def _add_render_options(p: argparse.ArgumentParser) -> None:
    _add_define_option(p)
    p.add_argument("--seed", type=_seed, default=0, help="random seed (default 0)")
    p.add_argument("--threads", type=_threads, default=os.cpu_count() or 1,
                   help="worker threads (default: all cores); the image does not depend on it")
    p.add_argument("--width", type=_side, help="override the camera's width in pixels")
    p.add_argument("--height", type=_side, help="override the camera's height in pixels")
    p.add_argument("--exposure", type=_exposure, default=0.0,
                   help="PNG preview exposure in stops (default 0)")
    p.add_argument("--quiet", action="store_true", help="no progress bar and no summary line")


def _add_cluster_options(p: argparse.ArgumentParser, tasks: str, task_spp: bool = False) -> None:
    """--workers and --scheduler (exclusive), and for a reference --task-spp: run on Dask."""
    g = p.add_argument_group("on a Dask cluster (the cluster extra: pip install '.[cluster]' in tracer's "
                             "folder)", tasks)
    where = g.add_mutually_exclusive_group()
    where.add_argument("--workers", type=_workers, metavar="N",
                       help="start a local Dask cluster of N single-threaded worker processes")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="use the existing Dask cluster whose scheduler is at ADDRESS (tcp://host:8786)")
    g.add_argument("--connect-timeout", type=_positive_float, metavar="SECONDS", default=None,
                   help="with --scheduler: seconds the scheduler has to answer, and again to have a "
                   "worker (default 20)")
    if task_spp:
        g.add_argument("--task-spp", type=_spp, metavar="N",
                       help="samples per pixel of a task, rounded down to a power-of-two number of the "
                       "render's leaves, or below one leaf to whole passes (default: about 4 tasks per "
                       "worker thread, and at most about 13 s of one thread's work each); the image does "
                       "not depend on it")


def _cluster(args: argparse.Namespace):
    """A Dask client for --workers or --scheduler (tracer.cluster.connect), or None for neither."""
    if args.connect_timeout is not None and args.scheduler is None:
        raise InputError("--connect-timeout is the wait for --scheduler", "command line")
    if args.workers is None and args.scheduler is None:
        return contextlib.nullcontext()
    from .cluster import CONNECT_SECONDS, connect

    return connect(args.workers, args.scheduler, args.connect_timeout or CONNECT_SECONDS)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    quiet = bool(getattr(args, "quiet", False))
    if quiet or "tracer.kernels.compiling" in sys.modules:
        from .kernels import compiling

        compiling.QUIET = quiet  # --quiet: no compile line on a terminal either
    previous = notices.set_handler(_print_note())
    # SIGTERM (kill, a batch scheduler's time limit) stops a command as Ctrl-C does, and neither
    # can be lost to a finalizer that drops its KeyboardInterrupt (tracer.interrupts).
    with interrupts.watching():
        try:
            code = args.run(args)
        except InputError as exc:
            print(f"tracer: error: {exc}", file=sys.stderr)
            return EXIT_BAD_INPUT
        except KeyboardInterrupt:
            print("tracer: interrupted", file=sys.stderr)
            return EXIT_INTERRUPTED
        except BrokenPipeError:
            # `tracer ... | head`: the reader left; say nothing more (and nothing at exit either).
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return 0
        finally:
            notices.set_handler(previous)
        if interrupts.pending() and code == 0:
            # A signal whose KeyboardInterrupt was dropped after the work's last check: the work
            # is done and written; the command still ends as interrupted.
            print("tracer: interrupted (after the work was done and written)", file=sys.stderr)
            return EXIT_INTERRUPTED
        return code


def _print_note():
    """A notes handler (``tracer.notices``) that prints each distinct note once on stderr (a
    command that loads a scene several times says it once)."""
    seen: set[str] = set()

    def handler(line: str) -> None:
        if line not in seen:
            seen.add(line)
            print(f"tracer: note: {line}", file=sys.stderr)

    return handler


def _strategy_from(args: argparse.Namespace, name: str, light_sampling: str | None = None,
                   light_selection: str | None = None, ris: tuple[int, str] | None = None,
                   heuristic: str | None = None, allocation: str | None = None):
    """The strategy ``name`` with the command line's options (``Strategy.from_options``); the
    light sampling is ``light_sampling``, else ``--light-sampling``, else the default; the light
    selection, ris's ``(candidates, sources)``, the heuristic and the allocation likewise
    (compare's options are lists, which its caller expands)."""
    from .strategy import Strategy

    def given(option):
        value = getattr(args, option, None)
        return value if isinstance(value, (str, int)) else None

    candidates, sources = ris or (given("ris_candidates"), given("ris_sources"))
    try:
        return Strategy.from_options(
            name, heuristic=heuristic or given("heuristic"),
            light_samples=getattr(args, "light_samples", None),
            bsdf_samples=getattr(args, "bsdf_samples", None), one_sample=getattr(args, "one_sample", None),
            light_selection=light_selection or given("light_selection"),
            light_sampling=light_sampling or given("light_sampling"),
            environment_sampling=given("environment_sampling"),
            allocation=allocation or given("allocation"),
            ris_candidates=candidates, ris_sources=sources)
    except ValueError as exc:
        raise InputError(str(exc), "command line") from None


def _exr_path(text: str) -> Path:
    """The output EXR, checked before any work starts: a .exr name, an existing writable folder,
    and neither it nor its PNG preview an existing folder."""
    output = Path(text)
    if output.suffix.lower() != ".exr":
        raise InputError("output must end in .exr", str(output))
    folder = output.parent if str(output.parent) else Path(".")
    try:
        if not folder.is_dir():
            raise InputError("output folder does not exist", str(folder))
        for path in (output, output.with_suffix(".png")):
            if path.is_dir():
                raise InputError("is a folder, not a file that can be written", str(path))
        # The temporary file's name is longer than the output's (atomic.TEMPORARY_TAG).
        if len(output.name.encode()) + 20 > os.pathconf(folder, "PC_NAME_MAX"):
            raise InputError("file name too long", str(output))
    except OSError as exc:  # a name too long for the file system, a loop of links, ...
        raise InputError(f"cannot use this output name: {exc.strerror or exc}", str(output)[:300]) from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError("output folder is not writable", str(folder))
    return output


def _output_folder(text: str) -> Path:
    """An output folder, checked before any work starts: not an existing file, and a file can be
    created in it. Folders that do not exist yet are created for the probe and removed again
    (the command creates them when it writes), so a refused or interrupted run leaves none."""
    import tempfile

    out = Path(text)
    if out.exists() and not out.is_dir():
        raise InputError("exists and is not a folder", str(out))
    missing = []
    parent = out
    while not parent.exists() and parent != parent.parent:
        missing.append(parent)
        parent = parent.parent
    created = []
    try:
        for folder in reversed(missing):
            folder.mkdir()
            created.append(folder)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as exc:
        raise InputError(f"cannot write into this folder: {exc.strerror or exc}", str(out)) from None
    finally:
        for folder in reversed(created):
            try:
                folder.rmdir()
            except OSError:
                pass
    return out


def _exposure(text: str) -> float:
    """An argparse type: exposure in stops, finite and within +-100 (2^100 already saturates
    every pixel; beyond that the scale overflows)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of stops, got '{text}'") from None
    if not -100.0 <= value <= 100.0:
        raise argparse.ArgumentTypeError(f"expected a number of stops in -100 .. 100, got {text}")
    return value


def _write_outputs(film, output: Path, exposure: float, half: bool) -> bool:
    """Write a finished film's EXR and its PNG preview beside it. Ctrl-C or SIGTERM during the
    writes is held until both files are complete; returns whether one arrived (then says so)."""
    from .imagefiles import write_exr, write_png

    png = output.with_suffix(".png")
    with interrupts.deferred() as deferred:
        write_exr(output, film, half=half)
        try:
            write_png(png, film.image(), exposure)
        except InputError as exc:
            raise InputError(f"{exc} ({output} was written)") from None
    if deferred:
        print(f"tracer: interrupted while writing; {output} and {png} were written first", file=sys.stderr)
    return bool(deferred)


def _finish(result, scene, strategy, output: Path, asked_spp: int, quiet: bool, exposure: float,
            half: bool = False) -> int:
    """Write the EXR and PNG of a render, report it on stderr, and return the exit status."""
    from .record import format_ranges

    film = result.film
    png = output.with_suffix(".png")
    if result.interrupted and result.samples == 0:
        print("tracer: interrupted before any sample was rendered: nothing written", file=sys.stderr)
        return EXIT_INTERRUPTED
    if _write_outputs(film, output, exposure, half):
        return EXIT_INTERRUPTED
    if result.nonfinite:
        print(f"tracer: warning: {result.nonfinite} samples were NaN or infinite and were set to 0",
              file=sys.stderr)
    if not quiet or result.interrupted:
        rate = result.samples / max(result.seconds, 1e-9)
        # The file's tracer:spp is the smallest count; a pass cut short leaves some pixels more.
        # The ranges kept are this run's (a resumed file lists its earlier ones too).
        note = (f" (interrupted, {asked_spp} spp were asked: every pixel holds {film.spp} spp or more, "
                f"up to {int(film.count.max())}; kept samples {format_ranges(result.drawn)} as "
                "seed:first-last)") if result.interrupted else ""
        label = strategy.label
        if film.record.auto:  # what auto chose: the strategy the file's record names
            from .strategy import Strategy

            label = f"auto -> {Strategy.from_record(film.record).label}"
        print(f"{scene.name}: {film.width}x{film.height}, {film.spp} spp, {label}{note}: "
              f"{result.seconds:.2f} s, {rate / 1e6:.2f} M samples/s -> {output}, {png}",
              file=sys.stderr)
    return EXIT_INTERRUPTED if result.interrupted else 0


def _warn_if_dark(scene) -> None:
    """A scene without any light renders black: say so rather than let a black image puzzle."""
    if not scene.has_lights:
        print(f"tracer: warning: {scene.path} has no lights (no emission, no point lights): the image "
              "will be black", file=sys.stderr)


def _refuse_existing_render(output: Path) -> None:
    """InputError before any rendering if the EXR or its PNG preview exists: a render never
    replaces what an earlier one computed unless asked (--force), as ``tracer reference`` does.
    Renders of two scenes with the same name (veach_mis.toml and mitsuba/veach_mis.xml) get the
    same default name; this is what stops the second from silently replacing the first."""
    exr, png = output, output.with_suffix(".png")
    if os.path.lexists(exr):
        raise InputError("a render exists here: --force replaces it, or -o OUT.exr writes another file",
                         str(exr))
    if os.path.lexists(png):
        raise InputError("a file exists where this render's PNG preview goes: --force replaces it, or "
                         "-o OUT.exr writes another file", str(png))


def cmd_render(args: argparse.Namespace) -> int:
    from . import scene as scene_mod
    from .render_loop import RenderSettings, render

    scene_path = scene_mod.resolve_scene(args.scene) if args.scene else scene_mod.default_scene_path()
    scene = scene_mod.load_scene(scene_path, args.width, args.height, parameters=_parameters(args))
    defaults = scene.render_defaults
    name = args.strategy or defaults.get("strategy", "mis")
    # auto chooses the light sampling itself: a scene's [render] light_sampling is not for it.
    strategy = _strategy_from(args, name, args.light_sampling or (defaults.get("light_sampling")
                                                                  if name != "auto" else None))
    spp = args.spp or defaults.get("spp", 64)
    sampler = args.sampler or defaults.get("sampler", DEFAULT_SAMPLER)
    # The default name tells settings apart (mis_balance, light_x4, sobol, seed 5), so that
    # renders with other options do not overwrite each other.
    seed_part = f"_seed{args.seed}" if args.seed else ""
    sampler_part = f"_{sampler}" if sampler != DEFAULT_SAMPLER else ""
    output = _exr_path(args.output or f"{scene.name}_{strategy.slug}{sampler_part}{seed_part}.exr")
    if not args.force:
        _refuse_existing_render(output)
    _warn_if_dark(scene)
    settings = RenderSettings(spp=spp, seed=args.seed, threads=args.threads, sampler=sampler)
    result = render(scene, strategy, settings, progress=not args.quiet)
    return _finish(result, scene, strategy, output, spp, args.quiet, args.exposure)


def cmd_reference(args: argparse.Namespace) -> int:
    from . import scene as scene_mod
    from .imagefiles import read_exr
    from .render_loop import RenderSettings, render
    from .strategy import Strategy

    scene_path = scene_mod.resolve_scene(args.scene)
    output = _exr_path(args.output or f"{scene_path.stem}_reference.exr")
    film, seed, first, sampler = None, args.seed, 0, args.sampler
    # Strategy's defaults, but the light sampling: None = the scene's [render] default, else area.
    defaults = {name: getattr(Strategy(), name) for name in ("heuristic", "light_samples", "bsdf_samples",
                                                               "one_sample", "light_selection", "allocation",
                                                               "environment_sampling")}
    defaults["light_sampling"] = None
    width, height = args.width, args.height
    if args.resume:
        if not output.is_file():
            raise InputError("--resume: no reference to resume", str(output))
        film = read_exr(output)
        if film.record.strategy != "mis":
            raise InputError("--resume: not an MIS reference", str(output))
        # The file's resolution and estimator settings, unless given (and then they must agree).
        width, height = width or film.width, height or film.height
        try:
            recorded = Strategy.from_record(film.record)
        except ValueError as exc:
            raise InputError(f"--resume: {exc}", str(output)) from None
        defaults.update({name: getattr(recorded, name) for name in defaults})
    elif output.exists() and not args.force:
        raise InputError("a reference exists here: --resume adds samples to it, --force replaces it",
                         str(output))
    for name, value in defaults.items():
        if getattr(args, name) is None:
            setattr(args, name, value)
    scene = scene_mod.load_scene(scene_path, width, height, parameters=_parameters(args))
    strategy = _strategy_from(args, "mis", args.light_sampling or scene.render_defaults.get("light_sampling"))
    _warn_if_dark(scene)
    if film is not None:
        if (film.width, film.height) != (scene.camera.width, scene.camera.height):
            raise InputError(f"--resume: the reference is {film.width}x{film.height}, not the "
                             f"{scene.camera.width}x{scene.camera.height} asked for", str(output))
        # The reference's seed (its last one, if merged from several) from above every index it
        # holds: fresh random numbers that never repeat the samples it has.
        held = film.record.samples or ()
        seed = film.record.seed if film.record.seed is not None else (held[-1][0] if held else 0)
        first = film.record.fresh_start(seed)
        sampler = film.record.sampler or DEFAULT_SAMPLER
        if args.sampler is not None and args.sampler != sampler:
            raise InputError(f"--resume: the reference was rendered with the {sampler} sampler, not "
                             f"{args.sampler} (its samples would not pool); leave --sampler out", str(output))
    else:
        sampler = sampler or scene.render_defaults.get("sampler", DEFAULT_SAMPLER)
    settings = RenderSettings(spp=args.spp, seed=seed, threads=args.threads, first_sample=first,
                              sampler=sampler)
    on_cluster = args.workers is not None or args.scheduler is not None
    if args.task_spp is not None and not on_cluster:
        raise InputError("--task-spp sizes the tasks of --workers or --scheduler", "command line")
    if on_cluster:  # before a local cluster takes seconds to start
        from .cluster import refuse_undistributable

        refuse_undistributable(strategy, "command line")
    # The files are written before a local cluster shuts down: its shutdown takes seconds, and a
    # second Ctrl-C then must not cost the finished work.
    with _cluster(args) as client:
        if client is None:
            try:
                result = render(scene, strategy, settings, film=film, progress=not args.quiet)
            except InputError as exc:
                raise InputError(f"--resume: {exc}" if film is not None else str(exc), str(output)) from None
            return _finish(result, scene, strategy, output, args.spp, args.quiet, args.exposure,
                           half=not args.float)
        from .cluster import ClusterLost, render_distributed

        try:
            result = render_distributed(client, scene, strategy, settings, film=film,
                                        progress=not args.quiet, task_spp=args.task_spp)
        except ClusterLost as exc:
            # Keep what finished, as an interrupt does, then say what failed.
            if exc.result is not None and exc.result.samples:
                _finish(exc.result, scene, strategy, output, args.spp, args.quiet, args.exposure,
                        half=not args.float)
            raise
        except InputError as exc:
            raise InputError(f"--resume: {exc}" if film is not None else str(exc), str(output)) from None
        return _finish(result, scene, strategy, output, args.spp, args.quiet, args.exposure,
                       half=not args.float)


def cmd_scenes(args: argparse.Namespace) -> int:
    """One line per shipped scene on stdout: its name and description (and with --paths its file)."""
    from .scene import shipped_scenes

    scenes = shipped_scenes()
    width = max(len(s.name) for s in scenes)
    for s in scenes:
        line = f"{s.name:<{width}}  {s.description}"
        print(f"{line}  ({s.path})" if args.paths else line)
    return 0


def cmd_merge(args: argparse.Namespace) -> int:
    from .film import merge_renders
    from .imagefiles import exr_is_half, read_exr

    output = _exr_path(args.output)
    a, b = read_exr(args.a), read_exr(args.b)
    merged = merge_renders(a, b, args.a, args.b)
    half = all(exr_is_half(p) for p in (args.a, args.b))
    if _write_outputs(merged, output, args.exposure, half):
        return EXIT_INTERRUPTED
    if not args.quiet:
        print(f"merged {a.spp} + {b.spp} spp -> {merged.spp} spp: {output}", file=sys.stderr)
    return 0


def cmd_convert(args: argparse.Namespace) -> int:
    from . import scene as scene_mod
    from .scene.toml_writer import write_scene

    scene_path = scene_mod.resolve_scene(args.scene)
    output = Path(args.output or f"{scene_path.stem}.toml")
    if output.suffix.lower() != ".toml":
        raise InputError("output must end in .toml", str(output))
    folder = output.parent if str(output.parent) else Path(".")
    if not folder.is_dir():
        raise InputError("output folder does not exist", str(folder))
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError("output folder is not writable", str(folder))
    try:
        same = scene_path.resolve() == output.resolve()
    except OSError:
        same = False
    if same:
        raise InputError("the output would replace the scene it is converted from", str(output))
    scene = scene_mod.load_scene(scene_path, width=args.width, height=args.height,
                                 parameters=_parameters(args))
    # The files are written together: a signal while they are is held until all are.
    with interrupts.deferred() as arrived:
        written = write_scene(scene, output, args.scene)
    back = scene_mod.load_scene(output)
    if back.digest != scene.digest:
        print(f"tracer: error: {output} reads back as another scene than {args.scene} (scene digests "
              f"{back.digest[:12]} and {scene.digest[:12]}): please report this", file=sys.stderr)
        return EXIT_CHECK_FAILED
    if not args.quiet:
        meshes = len(written) - 1
        print(f"{scene.name}: {len(scene.shapes)} shapes, {len(scene.materials.names) - 1} materials, "
              f"{len(scene.point_position)} point lights -> {output}"
              + (f" and {meshes} PLY file{'s' if meshes != 1 else ''} beside it" if meshes else ""),
              file=sys.stderr)
    if arrived:
        print(f"tracer: interrupted while writing; {output} was completed first", file=sys.stderr)
        return EXIT_INTERRUPTED
    return 0


def cmd_compare(args: argparse.Namespace) -> int:
    from .strategy import STRATEGIES, Strategy
    from .study import report
    from .study.compare import ALLOCATIONS, Comparison, product_of_options
    from .study.reference import independent_seeds, read_reference, scene_for_reference

    names = [n.strip() for n in args.strategies.split(",") if n.strip()]
    formats = [f.strip().lower() for text in args.figure_format or [] for f in text.split(",") if f.strip()]
    bad = [f for f in formats if f not in report.FIGURE_FORMATS]
    if bad:
        raise InputError(f"--figure-format: unknown format '{bad[0]}' (expected some of "
                         f"{', '.join(report.FIGURE_FORMATS)})", "command line")
    unknown = [n for n in names if n not in STRATEGIES]
    if unknown or not names:
        raise InputError(f"--strategies: unknown strategy '{unknown[0] if unknown else ''}' "
                         f"(expected some of {', '.join(STRATEGIES)})", "command line")
    reference = read_reference(args.reference, args.reference_layer, args.reference_spp)
    scene = scene_for_reference(args.scene, args.reference, reference, quiet=args.quiet)
    for x, y, w, h in args.crop or []:
        if x + w > reference.width or y + h > reference.height:
            raise InputError(f"--crop {x},{y},{w},{h} leaves the {reference.width}x{reference.height} image",
                             "command line")
    out = _output_folder(args.out)
    seeds = independent_seeds(reference, args.seed, args.sweep_seeds if args.sweep else 1, args.reference)
    comparison = Comparison(scene, reference, seeds[0], args.threads, progress=not args.quiet,
                            clock=args.clock)

    def run(strategy, sampler=DEFAULT_SAMPLER):  # a call of Comparison.perform
        if args.time:
            return "equal_time", (strategy, args.time, sampler)
        return "equal_spp", (strategy, args.spp, sampler)

    # Every strategy with every light sampling and selection asked for (those without light
    # samples once), and ris with every candidate count and source.
    samplings = args.light_sampling or [scene.render_defaults.get("light_sampling")]
    try:
        strategies, ris_heuristic = product_of_options(
            names, heuristics=args.heuristic, allocations=args.allocation, light_samplings=samplings,
            light_selections=args.light_selection, environment_samplings=args.environment_sampling,
            ris_settings=[(m, sources) for sources in args.ris_sources for m in args.ris_candidates],
            light_samples=args.light_samples, bsdf_samples=args.bsdf_samples, one_sample=args.one_sample)
    except ValueError as exc:
        raise InputError(str(exc), "command line") from None
    sampler_names = args.sampler or [scene.render_defaults.get("sampler", DEFAULT_SAMPLER)]

    mode = report.describe_mode(args.spp, args.time, args.clock)
    if not args.quiet:
        print(f"{scene.name}: {mode['description']} at {reference.width}x{reference.height}", file=sys.stderr)
    try:
        with _cluster(args) as client:
            items = [(strategy, sampler) for strategy in strategies for sampler in sampler_names]
            calls = [run(strategy, sampler) for strategy, sampler in items]
            if args.sweep:
                first_sampling = _strategy_from(args, "mis", samplings[0]).light_sampling
                calls += [run(Strategy("mis", ris_heuristic, n_light, n_bsdf,
                                       light_selection=args.light_selection[0],
                                       light_sampling=first_sampling), sampler_names[0])
                          for n_light, n_bsdf in ALLOCATIONS]
            results = comparison.perform(calls, client)
            runs, allocation = results[:len(items)], results[len(items):]
            sweep = comparison.sweeps(items, seeds, max_spp=args.spp, budget=args.time,
                                      client=client) if args.sweep else []
    except KeyboardInterrupt:
        # A strategy cut short would be compared at less time or fewer samples than the others.
        print(f"tracer: interrupted: the comparison is incomplete, nothing written to {out}", file=sys.stderr)
        return EXIT_INTERRUPTED
    _warn_if_reference_is_noisy(comparison.reference_relmse, runs, reference)
    # The report is many files; a signal while they are written is held until all are.
    with interrupts.deferred() as arrived:
        document = report.make_report(out, scene.name, args.reference, reference, runs, mode, sweep,
                                      allocation, args.crop, args.exposure, args.target, tuple(formats),
                                      say=None if args.quiet else lambda text: print(text, file=sys.stderr))
    if not args.quiet:
        width = max(len(r["name"]) for r in document["results"])
        seconds = "CPU s" if args.clock == "cpu" else "seconds"
        print(f"\n{'strategy':<{width}}  {'spp':>6} {seconds:>8} {'relMSE':>10} {'efficiency':>11}",
              file=sys.stderr)
        for r in document["results"]:
            print(f"{r['name']:<{width}}  {r['spp']:>6} {r['seconds']:>8.2f} "
                  f"{report.number(r['relmse']):>10} {report.number(r['efficiency']):>11}", file=sys.stderr)
        sweep_lines = report.terminal_tables(document)
        if sweep_lines:
            print("", *sweep_lines, sep="\n", file=sys.stderr)
    uncorrected = report.uncorrected_line(reference)
    if uncorrected:  # under the table it qualifies; with --quiet too: it changes what the numbers mean
        print(f"tracer: note: {uncorrected}", file=sys.stderr)
    if not args.quiet:
        print(f"-> {out / 'index.html'}", file=sys.stderr)
    if arrived:
        print(f"tracer: interrupted while writing the report; it was completed first: {out}", file=sys.stderr)
        return EXIT_INTERRUPTED
    return 0


# The reference's own noise, as a share of a strategy's measured relMSE, above which compare
# warns: the correction removes it on average, but the corrected value is then itself noisy.
NOISY_REFERENCE_SHARE = 0.1


def _warn_if_reference_is_noisy(reference_relmse: float | None, runs, reference) -> None:
    """One warning line when the reference's noise is a noticeable share of some strategy's
    measured (uncorrected) relMSE; none where that noise is not known (None). ``reference``: the
    ``study.reference.Reference``, whose kind says how to get a better one."""
    if reference_relmse is None:
        return
    worst = max(runs, key=lambda r: reference_relmse / max(r.measures["relmse_uncorrected"], 1e-300))
    measured = worst.measures["relmse_uncorrected"]
    if measured > 0.0 and reference_relmse > NOISY_REFERENCE_SHARE * measured:
        better = (f"tracer reference ... --resume -o {reference.path}" if reference.external is None
                  else "render it with more samples")
        print(f"tracer: warning: the reference's own noise (relMSE {reference_relmse:.3g}) is "
              f"{min(reference_relmse / measured, 1.0):.0%} of {worst.strategy.label}'s measured error "
              f"({measured:.3g}); it is subtracted from every error, but a longer reference would measure "
              f"better: {better}", file=sys.stderr)


def cmd_check(args: argparse.Namespace) -> int:
    from .kernels import prefer_shared

    prefer_shared()  # its entries' scenes share one build per strategy and sampler
    with _cluster(args) as client:
        return _check(args, client)


def _check(args: argparse.Namespace, client) -> int:
    from .study.check import create_baseline, find_default_baseline, format_table, parse_strategies, run_check

    create_options = {"--scenes": args.scenes, "--strategies": args.strategies, "--spp": args.spp,
                      "--seeds": args.seeds, "--reference-spp": args.reference_spp, "--size": args.size,
                      "--sampler": args.sampler}
    if args.create is None:
        given = [name for name, value in create_options.items() if value is not None]
        if given:
            raise InputError(f"{given[0]} goes with --create BASELINE", "command line")
    else:
        clash = [name for name, value in (("--baseline", args.baseline), ("--update", args.update),
                                          ("--seed-offset", args.seed_offset)) if value]
        if clash:
            raise InputError(f"--create writes a new baseline; {clash[0]} is for checking one",
                             "command line")
        for name in ("--scenes", "--strategies"):
            if not create_options[name]:
                raise InputError(f"--create needs {name}", "command line")
        result = create_baseline(args.create, args.scenes.split(","), parse_strategies(args.strategies),
                                 spp=args.spp or 16, seeds=args.seeds or 8,
                                 reference_spp=args.reference_spp or 1024, size=args.size or 64,
                                 threads=args.threads, sampler=args.sampler or DEFAULT_SAMPLER,
                                 client=client)
        print(f"baseline written: {args.create} ({len(result.measurements)} entries); check with "
              f"tracer check --baseline {args.create}", file=sys.stderr)
        return 0
    if args.baseline:
        baseline = Path(args.baseline)
    else:
        # Said first: the default depends on the current folder and on how tracer was installed.
        # (A baseline given with --baseline is not repeated here, so that bad input stays one
        # line; the last line names the baseline either way.)
        baseline, why = find_default_baseline()
        print(f"baseline: {baseline} ({why})", file=sys.stderr)
    result = run_check(baseline, update=args.update, out=_output_folder(args.out),
                       seed_offset=args.seed_offset, threads=args.threads, client=client)
    if args.update:
        print(f"baseline written: {baseline} ({len(result.measurements)} entries)", file=sys.stderr)
        return 0
    print(format_table(result.verdicts))
    if result.ok:
        print(f"check passed: {len(result.measurements)} entries of {baseline}", file=sys.stderr)
        return 0
    failing = sorted({v.entry for v in result.verdicts if not v.ok})
    folders = ", ".join(f"{folder}/" for folder in result.failure_folders.values())
    print(f"check FAILED: {', '.join(failing)} (baseline {baseline}); maps in {folders}", file=sys.stderr)
    return EXIT_CHECK_FAILED


def cmd_primer(args: argparse.Namespace) -> int:
    from .study.primer import main as primer_main

    return primer_main(_output_folder(args.out) if args.out else None, args.seed)


def cmd_stability(args: argparse.Namespace) -> int:
    from .kernels import prefer_shared
    from .study.stability import Cell, expectations, format_table, run_suite

    prefer_shared()  # its cases' scenes share one build per strategy and sampler

    out = _output_folder(args.out)
    doc = run_suite(out, spp=args.spp, seed=args.seed, threads=args.threads, reference_spp=args.reference_spp,
                    sampler=args.sampler)
    print(format_table([Cell(**c) for c in doc["cells"]]))
    print("\nVeach's bound for balance MIS (variances summed over 144 shading points):")
    for name, b in doc["veach_bound"].items():
        technique = b["technique"]
        print(f"  {name:<22} balance mis {b['mis_balance']:.4g} <= {technique} {b[technique]:.4g} "
              f"+ mu^2/2 {b['slack']:.4g}")
    problems = expectations(doc)
    for problem in problems:
        print(f"FAIL {problem}")
    print(f"-> {out / 'stability.json'}, {out / 'stability.png'}", file=sys.stderr)
    return EXIT_CHECK_FAILED if problems else 0
