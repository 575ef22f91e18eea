"""MkDocs hooks: the pages and files of the site that are made, not written.

- ``reference/cli.md``, ``reference/plugins.md``, ``reference/scene-keys.md``: generated from
  the code by ``tracer.manual`` on every build, so they always list what this tracer offers;
- ``guide/notebook.md``: ``notebooks/tutorial.ipynb`` with its stored outputs (text and
  images; the notebook is not run here: ``tests/test_notebook.py`` runs it);
- ``changelog.md``: the repository's ``CHANGELOG.md``;
- ``renders/...``: the repository's images, which the guide and results pages show.

None of them is written into ``docs/``: they exist only in the build (MkDocs' generated files).
"""

from __future__ import annotations

import base64
import json
import re
from pathlib import Path

from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parent.parent
NOTEBOOK = ROOT / "notebooks" / "tutorial.ipynb"
NOTEBOOK_PAGE = "guide/notebook.md"
INTRO = ROOT / "docs" / "guide" / "notebook-intro.md"  # the page's text above the notebook (not a page)


def on_files(files: Files, config) -> Files:
    from tracer import manual

    for uri, text in manual.pages().items():
        files.append(File.generated(config, uri, content=text))
    files.append(File.generated(config, "changelog.md",
                                content=(ROOT / "CHANGELOG.md").read_text(encoding="utf-8")))
    page, images = notebook_page(NOTEBOOK, INTRO.read_text(encoding="utf-8"))
    files.append(File.generated(config, NOTEBOOK_PAGE, content=page))
    for uri, data in images.items():
        files.append(File.generated(config, uri, content=data))
    for image in sorted((ROOT / "renders").rglob("*.png")):
        files.append(File.generated(config, image.relative_to(ROOT).as_posix(), abs_src_path=str(image)))
    return files


def _text(value) -> str:
    return "".join(value) if isinstance(value, list) else str(value)


def _site_links(markdown: str) -> str:
    """The notebook links the documentation as files of the repository (``../docs/guide/x.md``,
    which work in Jupyter); on the site the same pages are the notebook page's neighbours."""
    return re.sub(r"\]\(\.\./docs/([^)#]*)", lambda m: "](../" + m.group(1), markdown)


def notebook_page(path: Path, intro: str) -> tuple[str, dict[str, bytes]]:
    """Markdown of the notebook ``path`` after ``intro``: its markdown cells as they are, code
    cells fenced, their stored outputs below them (text fenced, PNGs as images of the page),
    and the images' bytes by site path."""
    notebook = json.loads(path.read_text(encoding="utf-8"))
    parts = [intro.rstrip() + "\n"]
    images: dict[str, bytes] = {}
    for index, cell in enumerate(notebook["cells"]):
        source = _text(cell["source"]).rstrip()
        if cell["cell_type"] == "markdown":
            # The notebook's own headings sit one level below the page's title.
            parts.append(_site_links(re.sub(r"^(#+) ", r"#\1 ", source, flags=re.M)))
            continue
        if cell["cell_type"] != "code":
            continue
        parts.append("```python\n" + source + "\n```")
        for number, output in enumerate(cell.get("outputs", [])):
            data = output.get("data", {})
            if output["output_type"] == "stream":
                parts.append("```text\n" + _text(output["text"]).rstrip() + "\n```")
            elif "image/png" in data:
                uri = f"guide/notebook/cell{index}_{number}.png"
                images[uri] = base64.b64decode(_text(data["image/png"]))
                parts.append(f"![output of the cell above](notebook/cell{index}_{number}.png)")
            elif "text/plain" in data:
                parts.append("```text\n" + _text(data["text/plain"]).rstrip() + "\n```")
            elif output["output_type"] == "error":
                parts.append("```text\n" + "\n".join(output.get("traceback", [])) + "\n```")
    return "\n\n".join(parts) + "\n", images
