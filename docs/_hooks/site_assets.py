"""A mkdocs hook: the site serves its own MathJax, so that every page's equations render
without a network (MathJax 2.7 from the `jupyter-server-mathjax` package, copied into
`_static/mathjax/` of the built site; `docs/_static/mathjax.js` configures it)."""

import shutil
from importlib import resources


def on_post_build(config, **kwargs):
    static = resources.files("jupyter_server_mathjax") / "static"
    target = f"{config['site_dir']}/_static/mathjax"
    with resources.as_file(static) as source:
        shutil.copytree(source, target, dirs_exist_ok=True)
