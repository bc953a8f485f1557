"""A mkdocs hook: the pages' key figures are the notebooks' own, taken from the notebooks as
the site executes them (mkdocs-jupyter), so that a page shows the figure its notebook draws
today and nothing is committed as an image.

A code cell tagged `figure-NAME` (cell metadata `tags`) gives `figures/NAME.png`: the first
PNG among its outputs. Pages show it as `![...](figures/NAME.png)` (relative to the page).
A tagged cell that draws no PNG, or a figure no notebook gives, fails the build."""

import base64
import json
import pathlib
import re

from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File

_TAG = re.compile(r"^figure-([a-z0-9-]+)$")
_CELL = re.compile(r'<div class="jp-Cell [^"]*\bcelltag_figure-([a-z0-9-]+)\b[^"]*">')
_NEXT_CELL = re.compile(r'<div class="jp-Cell ')
_PNG = re.compile(r'src="data:image/png;base64,([A-Za-z0-9+/=\s]+)"')

_figures: dict[str, File] = {}  # name -> the generated file (filled by the notebook's page)
_filled: set[str] = set()


def _tags(notebook: pathlib.Path) -> list[str]:
    cells = json.loads(notebook.read_text())["cells"]
    names = []
    for cell in cells:
        for tag in cell.get("metadata", {}).get("tags", []):
            match = _TAG.match(tag)
            if match:
                if cell["cell_type"] != "code":
                    raise PluginError(f"{notebook.name}: the tag {tag!r} is on a markdown cell.")
                names.append(match.group(1))
    return names


def on_files(files, config, **kwargs):
    _figures.clear()
    _filled.clear()
    notebooks = sorted(pathlib.Path(config["docs_dir"], "notebooks").glob("*.ipynb"))
    for notebook in notebooks:
        for name in _tags(notebook):
            if name in _figures:
                raise PluginError(f"two notebook cells are tagged figure-{name}.")
            file = File.generated(config, f"figures/{name}.png", content=b"")
            files.append(file)
            _figures[name] = file
    return files


def on_page_content(html, page, config, files, **kwargs):
    if not page.file.src_uri.endswith(".ipynb"):
        return html
    for match in _CELL.finditer(html):
        name = match.group(1)
        end = len(html)  # the cell ends where a cell without its tag starts (the template
        for following in _NEXT_CELL.finditer(html, match.end()):  # nests its divs)
            if (
                f"celltag_figure-{name}"
                not in html[following.start() : html.find(">", following.start())]
            ):
                end = following.start()
                break
        cell = html[match.end() : end]
        png = _PNG.search(cell)
        if png is None:
            raise PluginError(
                f"{page.file.src_uri}: the cell tagged figure-{name} drew no PNG figure."
            )
        _figures[name].content_bytes = base64.b64decode(re.sub(r"\s", "", png.group(1)))
        _filled.add(name)
    return html


def on_env(env, config, files, **kwargs):
    missing = sorted(set(_figures) - _filled)
    if missing:  # before the files are copied: never an empty image in the site
        raise PluginError(f"no notebook page gave the key figures {missing}.")
    return env
