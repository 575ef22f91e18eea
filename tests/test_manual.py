"""The generated reference pages (tracer/manual.py) list everything the code offers: every
flag of every command, every registered plug-in of every kind with each material parameter,
every strategy option, every scene key. A flag, plug-in or key added without appearing there
fails here. Not statistical: plain membership checks on the generated Markdown."""

import pytest

from tracer import manual, plugins, strategy
from tracer.scene import keys


@pytest.fixture(scope="module")
def pages():
    return manual.pages()


def test_every_flag_of_every_command_is_listed(pages):
    cli = pages["reference/cli.md"]
    commands = manual.commands()
    expected = {"render", "reference", "compare", "check", "primer", "stability", "merge", "convert"}
    assert expected <= set(commands)
    for name, parser in commands.items():
        section = cli.split(f"## tracer {name}\n", 1)[1].split("\n## tracer ", 1)[0]
        for action in manual.flags(parser):
            for spelling in action.option_strings or [action.metavar or action.dest]:
                assert f"| `{spelling}`" in section or f", `{spelling}`" in section, (name, spelling)


def test_every_plugin_and_material_parameter_is_listed(pages):
    page = pages["reference/plugins.md"]
    for kind in plugins.KINDS:
        registered = plugins.registry(kind)
        assert registered, kind
        for plugin in registered.values():
            assert f"`{plugin.name}`" in page or f"### {plugin.name}\n" in page, (kind, plugin.name)
    for material in plugins.registry("material").values():
        section = page.split(f"### {material.name}\n", 1)[1].split("\n### ", 1)[0]
        for param in material.params:
            # What the readers set (a blend's part codes) is no key a scene gives: not listed.
            assert (f"`{param.name}`" in section) != param.internal, (material.name, param.name)


def test_every_strategy_option_has_a_line(pages):
    page = pages["reference/plugins.md"]
    for names, docs in ((strategy.STRATEGIES, strategy.STRATEGY_DOCS),
                        (strategy.HEURISTICS, strategy.HEURISTIC_DOCS),
                        (strategy.ALLOCATIONS, strategy.ALLOCATION_DOCS),
                        (strategy.RIS_SOURCES, strategy.RIS_SOURCE_DOCS)):
        assert set(names) == set(docs)
        for name in names:
            assert f"| `{name}` | {manual.cell(docs[name])} |" in page, name


def test_every_scene_key_is_listed(pages):
    page = pages["reference/scene-keys.md"]
    for section in keys.SECTIONS:
        part = page.split(f"## {manual.code(section.header)}\n", 1)[1].split("\n## ", 1)[0]
        for key in section.keys:
            assert f"| `{key.name}` |" in part, (section.header, key.name)


def test_table_cells_are_escaped():
    """A help text with a pipe, markup or a line break stays inside its cell."""
    row = manual.table(("a", "b"), [("x | y", "<b>bold</b>\nnext")]).splitlines()[2]
    assert row == "| x &#124; y | &lt;b&gt;bold&lt;/b&gt; next |"
