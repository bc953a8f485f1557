"""A mkdocs hook: the key figures of the reference pages, drawn from the repository's own
records when the site is built (nothing committed as an image):

- `figures/performance.png`: each benchmark's recorded ratios against the reference timed in
  the same run (`benchmarks/results.json`, the first device's; `run_all.checked_ratios`'s
  rule: every number whose key names a speedup, a ratio or an `_over_`);
- `figures/float32.png`: float32 against float64, the relative RMS difference of each
  problem's methods (`benchmarks/results.json`'s `float32_accuracy`);
- `figures/layers.png`: the package's layers, imports flowing down (`tests/test_layout.py`'s
  `LAYERS`, read from its source).
"""

import ast
import io
import json
import pathlib
import re

from mkdocs.structure.files import File

_RATIO = re.compile(r"(^|_)(speedup|ratio)(_|$)|_over_")


def _ratios(value, path=""):
    if isinstance(value, dict):
        for k, v in value.items():
            if k in ("target", "targets", "command"):
                continue
            label = f"{path}.{k}" if path else k
            if isinstance(v, int | float) and not isinstance(v, bool) and _RATIO.search(k):
                yield label, float(v)
            else:
                yield from _ratios(v, label)
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _ratios(v, f"{path}[{i}]")


def _png(fig) -> bytes:
    import matplotlib.pyplot as plt

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return buffer.getvalue()


def _performance(benchmarks) -> bytes:
    import matplotlib.pyplot as plt

    rows = [(f"{name}: {label}", v) for name, b in benchmarks.items()
            for label, v in _ratios(b) if v > 0][:40]  # fmt: skip
    fig, ax = plt.subplots(figsize=(9, 0.22 * len(rows) + 1.2))
    ax.barh(range(len(rows)), [v for _, v in rows], color="C0")
    ax.axvline(1.0, color="k", lw=0.8)
    ax.set_xscale("log")
    ax.set_yticks(range(len(rows)), [n for n, _ in rows], fontsize=7)
    ax.invert_yaxis()
    ax.set_xlabel("ratio to the reference timed in the same run [-] (benchmarks/results.json)")
    return _png(fig)


def _float32(benchmarks) -> bytes:
    import matplotlib.pyplot as plt

    rows = [r for r in benchmarks["float32_accuracy"]["rows"] if r["noise"] == "own"]
    labels = [f"{r['problem']}: {r['method']}" for r in rows]
    fig, ax = plt.subplots(figsize=(7, 0.25 * len(rows) + 1.2))
    ax.barh(range(len(rows)), [max(r["rel_rms_diff"], 1e-12) for r in rows], color="C1")
    ax.set_xscale("log")
    ax.set_yticks(range(len(rows)), labels, fontsize=7)
    ax.invert_yaxis()
    ax.set_xlabel("float32 against float64: relative RMS difference of the metric [-]")
    return _png(fig)


def _layers(root: pathlib.Path) -> bytes:
    import matplotlib.pyplot as plt

    tree = ast.parse((root / "tests" / "test_layout.py").read_text())
    layers = next(ast.literal_eval(n.value) for n in tree.body if isinstance(n, ast.Assign)
                  and getattr(n.targets[0], "id", "") == "LAYERS")  # fmt: skip
    top = ["cli, verbs, report, recording (the commands)"] + list(reversed(layers))
    fig, ax = plt.subplots(figsize=(5, 0.45 * len(top) + 0.4))
    for i, name in enumerate(top):
        y = len(top) - i
        ax.text(0.5, y, name, ha="center", va="center", fontsize=9,
                bbox={"boxstyle": "round", "fc": "0.95", "ec": "0.5"})  # fmt: skip
        if i < len(top) - 1:
            ax.annotate("", (0.5, y - 0.72), (0.5, y - 0.28), arrowprops={"arrowstyle": "->"})
    ax.set_xlim(0, 1)
    ax.set_ylim(0.4, len(top) + 0.6)
    ax.axis("off")
    ax.set_title("visjax's layers: each imports only those below it", fontsize=9)
    return _png(fig)


def on_files(files, config, **kwargs):
    import matplotlib

    matplotlib.use("Agg")
    root = pathlib.Path(config["docs_dir"]).parent
    devices = json.loads((root / "benchmarks" / "results.json").read_text())["devices"]
    benchmarks = next(iter(devices.values()))["benchmarks"]
    for name, content in (
        ("performance", _performance(benchmarks)),
        ("float32", _float32(benchmarks)),
        ("layers", _layers(root)),
    ):
        files.append(File.generated(config, f"figures/{name}.png", content=content))
    return files
