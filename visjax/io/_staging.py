"""Staged (atomic) output folders: a command writes into a hidden folder beside its final
`--out` and its files are moved into place only when it succeeded, so a failure leaves
nothing half-written. While a staged output is open, what is printed and what summaries
record name the final folder, never the staging one."""

import contextlib
import contextvars
import os
import shutil
import sys
import tempfile
from pathlib import Path

_STAGED: contextvars.ContextVar[tuple[str, str] | None] = contextvars.ContextVar(
    "visjax_staged_output", default=None
)


def user_path(text: str) -> str:
    """`text` with the staging folder of the open staged output replaced by the final
    folder the user asked for (unchanged outside a staged output)."""
    staged = _STAGED.get()
    return text if staged is None else text.replace(staged[0], staged[1])


def unstaged(tree):
    """A JSON-like tree (dicts, lists, strings) with every string passed through
    `user_path`."""
    if isinstance(tree, str):
        return user_path(tree)
    if isinstance(tree, dict):
        return {k: unstaged(v) for k, v in tree.items()}
    if isinstance(tree, (list, tuple)):
        return type(tree)(unstaged(v) for v in tree)
    return tree


class _Renaming:
    """A text stream that writes the final output folder where the staging one is named."""

    def __init__(self, stream):
        self.stream = stream

    def write(self, text):
        return self.stream.write(user_path(text))

    def __getattr__(self, name):
        return getattr(self.stream, name)


def check_output_path(out, *, file: bool = False) -> None:
    """An output path, checked before any work: a folder that can be created or written
    (`file=True`: a `.npz` or `.csv` file that can be written, not a folder); `None` passes.
    **Raises:** `ValueError` saying what is wrong."""
    if out is None:
        return
    path = Path(out)
    if file and path.suffix.lower() not in (".npz", ".csv"):
        raise ValueError(f"--out {out!r} must end in .npz or .csv")
    if file and path.is_dir():
        raise ValueError(f"--out {out!r} is a folder, not a file")
    if not file and path.exists() and not path.is_dir():
        raise ValueError(f"--out {out!r} exists and is not a folder")
    parent = path if path.exists() and not file else path.parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"--out {out!r}: {str(parent)!r} is not writable")


@contextlib.contextmanager
def staged_output(final, *, file: bool = False):
    """Stage an output folder (or, with `file=True`, one output file) and move it into place
    when the block exits without an exception; on an exception nothing is moved and the
    staging folder is removed.

    **Arguments:**

    - `final`: the folder (or file) the user asked for; made if missing. An existing
        folder keeps its other contents; an entry of the same name is replaced whole.
    - `file`: stage one file instead of a folder.

    **Yields:** the path to write to (a hidden `.visjax-*` folder beside `final`, or a file
    inside it). Inside the block, `sys.stdout` names `final` where the staging path is
    printed, and `visjax.io.write_summary` records `final` in place of the staging path.
    """
    final = Path(final)
    anchor = final if final.exists() else final.parent
    while not anchor.exists():
        anchor = anchor.parent
    staging = Path(tempfile.mkdtemp(prefix=".visjax-", dir=anchor))
    target = staging / final.name if file else staging
    token = _STAGED.set((str(target), str(final)))
    stdout = sys.stdout
    sys.stdout = _Renaming(stdout)
    try:
        yield target
        if file:
            final.parent.mkdir(parents=True, exist_ok=True)
            os.replace(target, final)
        else:
            final.mkdir(parents=True, exist_ok=True)
            for item in staging.iterdir():
                destination = final / item.name
                if destination.is_dir():
                    shutil.rmtree(destination)
                os.replace(item, destination)
    finally:
        sys.stdout = stdout
        _STAGED.reset(token)
        shutil.rmtree(staging, ignore_errors=True)
