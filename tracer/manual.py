"""The documentation site's reference pages, generated from the code so they cannot drift.

``pages()`` returns Markdown for three pages of ``docs/reference/``: every command and flag of
the command line (from the argparse parser ``tracer.cli.build_parser``), every registered
plug-in of every kind with its parameters (from ``tracer.plugins``' registries and the
strategy tables of ``tracer.strategy``), and every key of the scene format (from the tables the
TOML reader checks against, ``tracer.scene.keys``). ``docs/hooks.py`` hands them to MkDocs at
build time; ``tests/test_manual.py`` checks that nothing the code offers is missing from them.

Nothing here is needed to render: it imports the plug-in modules (and so numba) when called.
"""

from __future__ import annotations

import argparse
import html

GENERATED = "*This page is generated from the code (`tracer/manual.py`) when the site is built.*\n"


def cell(text: object) -> str:
    """``text`` made safe for one cell of a Markdown table: HTML escaped, pipes and newlines
    (which would end the cell or the row) replaced."""
    return html.escape(" ".join(str(text).split()), quote=False).replace("|", "&#124;")


def table(header: tuple[str, ...], rows: list[tuple[object, ...]]) -> str:
    """A Markdown table of ``rows`` under ``header``, every cell escaped."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell(value) for value in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def code(text: object) -> str:
    """``text`` as inline code (backticks doubled where the text has one)."""
    text = str(text)
    return f"`` {text} ``" if "`" in text else f"`{text}`"


# --- the command line -------------------------------------------------------------------------


def commands(parser: argparse.ArgumentParser | None = None) -> dict[str, argparse.ArgumentParser]:
    """Command name -> its subparser, in the order ``tracer --help`` lists them."""
    from tracer.cli import build_parser

    parser = parser or build_parser()
    for action in parser._actions:  # argparse keeps subparsers only here
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices.items())
    return {}


def flags(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    """The parser's arguments and options as the help lists them, ``--help`` left out."""
    return [a for a in parser._actions if not isinstance(a, argparse._HelpAction)]


def _flag_name(action: argparse.Action) -> str:
    """How the argument is spelled, as Markdown: each option string as code, then its value's
    name (``-o``, ``--output`` ``OUTPUT``); a positional argument by its name."""
    if not action.option_strings:
        return code(action.metavar or action.dest)
    spelled = ", ".join(code(option) for option in action.option_strings)
    if action.nargs != 0:
        spelled += " " + code(action.metavar or action.dest.upper())
    return spelled


def _help(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    if not action.help or action.help == argparse.SUPPRESS:
        return ""
    return parser._get_formatter()._expand_help(action)  # fills %(default)s as --help does


def _choices(action: argparse.Action) -> str:
    if action.choices is None or isinstance(action.choices, dict):
        return ""
    return ", ".join(str(c) for c in action.choices)


def cli_page() -> str:
    """The command-line reference: each command's usage, description and flags."""
    from tracer.cli import build_parser

    parser = build_parser()
    out = ["# Command line\n", GENERATED,
           "Every command of `tracer`, with every argument and option as `tracer COMMAND --help` "
           "prints it. `python -m tracer` is the same program.\n",
           "```\n" + parser.format_usage().strip() + "\n```\n"]
    for name, sub in commands(parser).items():
        out.append(f"## tracer {name}\n")
        out.append("```\n" + sub.format_usage().strip() + "\n```\n")
        if sub.description:
            out.append(sub.description.strip() + "\n")
        rows = [(_flag_name(a), _help(sub, a), _choices(a)) for a in flags(sub)]
        out.append(table(("argument", "meaning", "choices"), rows))
    return "\n".join(out)


# --- plug-ins and strategies ------------------------------------------------------------------


def _param_range(p) -> str:
    if p.choices:
        return "one of " + ", ".join(p.choices)
    if p.boolean:
        return "true or false"
    lo = "" if p.lo is None else ("> " if p.lo_open else ">= ") + f"{p.lo:g}"
    hi = "" if p.hi is None else f"<= {p.hi:g}"
    return " and ".join(x for x in (lo, hi) if x) or "any finite number"


def _param_default(p) -> str:
    if p.default is None:
        return "required"
    if isinstance(p.default, bool):
        return "true" if p.default else "false"
    if isinstance(p.default, tuple):
        return "[" + ", ".join(f"{x:g}" for x in p.default) + "]"
    return f"{p.default:g}" if isinstance(p.default, float) else str(p.default)


def plugins_page() -> str:
    """The plug-in reference: strategies, then every registered plug-in of every kind."""
    from tracer import plugins, strategy

    out = ["# Strategies and plug-ins\n", GENERATED,
           "What a render can be asked for: the strategies and their options (`--strategy`, "
           "`--heuristic`, `--allocation`, `--ris-sources`, `--environment-sampling`), then every plug-in registered in "
           "`tracer.plugins`, kind by kind, with what it declares. A user's own plug-in "
           "appears here once its module is imported (see the developer guide).\n",
           "## Strategies\n",
           table(("strategy", "what it does"), [(code(s), strategy.STRATEGY_DOCS[s])
                                                 for s in strategy.STRATEGIES]),
           "## MIS heuristics\n",
           table(("heuristic", "weights"), [(code(h), strategy.HEURISTIC_DOCS[h])
                                             for h in strategy.HEURISTICS]),
           "## Sample allocation\n",
           table(("allocation", "how `mis` splits its samples"),
                 [(code(a), strategy.ALLOCATION_DOCS[a]) for a in strategy.ALLOCATIONS]),
           "## RIS candidate sources\n",
           table(("source", "where `ris`'s candidates come from"),
                 [(code(s), strategy.RIS_SOURCE_DOCS[s]) for s in strategy.RIS_SOURCES]),
           "## Environment sampling\n",
           table(("environment sampling", "how `--environment-sampling` light-samples an environment map"),
                 [(code(s), strategy.ENVIRONMENT_SAMPLING_DOCS[s]) for s in strategy.ENVIRONMENT_SAMPLINGS])]
    kinds = {
        "material": ("Materials", "`type` of a `[materials.NAME]` table"),
        "light_technique": ("Light techniques", "how a light sample draws a direction toward one emitter"),
        "light_selection": ("Light selections", "`--light-selection`: which emitter a light sample samples"),
        "sampler": ("Samplers", "`--sampler`: where a render's random numbers come from"),
        "direction": ("Direction techniques", "how a direction sample is drawn (chosen by the strategy)"),
        "combiner": ("Combiners", "how a point's light and direction samples add up "
                     "(chosen by the strategy)"),
    }
    for kind, (title, what) in kinds.items():
        registered = plugins.registry(kind)
        out.append(f"## {title}\n")
        out.append(f"{what}; kind `{kind}`, package `{plugins.PACKAGES[kind]}`.\n")
        if kind == "material":
            for m in registered.values():
                out.append(f"### {m.name}\n")
                out.append(f"{m.doc} (module `{m.module}`).\n")
                rows = [(code(p.name), ("number" if p.size == 1 and not (p.choices or p.boolean)
                         else ("name" if p.choices else "boolean" if p.boolean else f"{p.size} numbers"))
                         + (" or a texture" if p.texture else ""),
                         _param_range(p), _param_default(p), p.doc) for p in m.params if not p.internal]
                rows.append((code("twosided"), "boolean", "true or false", "true",
                             "reflects on both sides (false: black from behind)"))
                out.append(table(("key", "type", "range", "default", "meaning"), rows))
            continue
        rows = []
        for p in registered.values():
            extra = []
            if kind == "light_technique":
                extra.append("emitters: " + ", ".join(p.emitters))
                if p.light_samplings:
                    extra.append("--light-sampling: " + ", ".join(p.light_samplings))
                if p.delta:
                    extra.append("delta light")
            elif kind == "light_selection" and p.per_point:
                extra.append("pmf depends on the shading point")
            elif kind == "sampler":
                extra.append(f"{p.replicates} replicates" if p.replicates else "independent samples")
            elif kind == "combiner" and p.resamples:
                extra.append("resamples candidates")
            rows.append((code(p.name), p.doc, f"{p.dims}", "; ".join(extra), f"`{p.module}`"))
        out.append(table(("name", "what it does", "numbers drawn", "declares", "module"), rows))
    return "\n".join(out)


# --- the scene format -------------------------------------------------------------------------


def scene_keys_page() -> str:
    """The scene-format reference: every table and key the TOML reader accepts."""
    from tracer.scene import keys

    out = ["# Scene keys\n", GENERATED,
           "Every key a TOML scene may hold, table by table, as the reader checks them "
           "(`tracer/scene/keys.py`). A key not listed is refused, with the closest known key "
           "named. Material parameters are on the [plug-in page](plugins.md#materials). "
           "The [scene format](../SCENE_FORMAT.md) explains how the keys fit together.\n"]
    for section in keys.SECTIONS:
        out.append(f"## {code(section.header)}\n")
        out.append(section.doc + "\n")
        rows = [(code(k.name), k.type, k.default, k.doc) for k in section.keys]
        out.append(table(("key", "type", "default", "meaning"), rows))
    return "\n".join(out)


def pages() -> dict[str, str]:
    """Path under ``docs/`` -> Markdown of every generated reference page."""
    return {"reference/cli.md": cli_page(), "reference/plugins.md": plugins_page(),
            "reference/scene-keys.md": scene_keys_page()}
