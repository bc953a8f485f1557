"""A mkdocs hook: every public name a guide or paper page writes as code links to its entry
in the API reference, so that a reader goes from the prose to the reference in one click.

The names are those the API pages document (their `::: visjax.module` directives, each
module's public members, read with griffe as mkdocstrings reads them). On a page outside
`api/`, the first inline code span of each name becomes a link to its entry:
`` `run` ``, `` `run(estimator, stream)` ``, `` `studies.sweep` `` or
`` `visjax.studies.sweep` `` (a name found under several paths links to the shortest; two
of the same length, to neither). Code blocks, headings and spans already inside a link are
left as they are; a link to an entry that does not exist fails the strict build (mkdocs'
anchor validation)."""

import pathlib
import posixpath
import re
import sys

import griffe

_DIRECTIVE = re.compile(r"^::: (visjax(?:\.\w+)*)\s*$", re.M)
_FENCE = re.compile(r"^[ \t]*(```|~~~)[^\n]*\n.*?^[ \t]*\1[ \t]*$", re.M | re.S)
_LINK = re.compile(r"\[[^\]]*\]\([^)\s]*\)")  # link text may span lines
_HEADING = re.compile(r"^[ \t]*#.*$", re.M)
_SPAN = re.compile(r"(?<!`)`((?:visjax\.)?[A-Za-z_][\w.]*?)(\([^`]*\))?`(?!`)")

_entries: dict[str, str] = {}  # full path -> API page (src_uri)


def _documented(docs_dir: pathlib.Path) -> dict[str, str]:
    sys.path.insert(0, str(docs_dir / "_griffe"))
    try:
        from public_reexports import PublicReexports
    finally:
        sys.path.pop(0)
    extensions = griffe.load_extensions(PublicReexports())
    package = griffe.load("visjax", search_paths=[str(docs_dir.parent)], extensions=extensions)
    entries = {}
    for page in sorted((docs_dir / "api").glob("*.md")):
        uri = f"api/{page.name}"
        for target in _DIRECTIVE.findall(page.read_text()):
            obj = package[target.removeprefix("visjax.")] if target != "visjax" else package
            if obj.is_module:
                for name, member in obj.members.items():
                    if member.is_public and not member.is_module:
                        entries.setdefault(f"{target}.{name}", uri)
            else:
                entries.setdefault(target, uri)
    return entries


def on_config(config, **kwargs):
    _entries.clear()
    _entries.update(_documented(pathlib.Path(config["docs_dir"])))
    return config


def _resolve(text: str) -> str | None:
    if len(text.rsplit(".", 1)[-1]) < 3:
        return None  # `A`, `t`, `H`: a symbol of the prose, not the API's
    full = text if text.startswith("visjax.") else None
    if full is not None:
        return full if full in _entries else None
    found = [path for path in _entries if path.endswith("." + text)]
    if not found:
        return None
    shortest = min(len(p) for p in found)
    best = [p for p in found if len(p) == shortest]
    return best[0] if len(best) == 1 else None


def _link_spans(text: str, here: str, linked: set[str]) -> str:
    protected = [m.span() for m in _LINK.finditer(text)]
    protected += [m.span() for m in _HEADING.finditer(text)]

    def replace(match):
        if any(a <= match.start() < b for a, b in protected):
            return match.group(0)
        full = _resolve(match.group(1))
        if full is None or full in linked:
            return match.group(0)
        linked.add(full)
        target = posixpath.relpath(_entries[full], posixpath.dirname(here) or ".")
        return f"[{match.group(0)}]({target}#{full})"

    return _SPAN.sub(replace, text)


def on_page_markdown(markdown, page, config, files, **kwargs):
    here = page.file.src_uri
    if here.startswith("api/") or not here.endswith(".md"):
        return markdown
    linked: set[str] = set()
    out, last = [], 0
    for fence in _FENCE.finditer(markdown):
        out.append(_link_spans(markdown[last : fence.start()], here, linked))
        out.append(fence.group(0))
        last = fence.end()
    out.append(_link_spans(markdown[last:], here, linked))
    return "".join(out)
