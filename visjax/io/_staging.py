"""Staged (atomic) output folders: a command writes into a hidden folder beside its final
`--out` and its files are moved into place only when it succeeded, so a failure leaves
nothing half-written. While a staged output is open, what is printed and what summaries
record name the final folder, never the staging one."""

import contextlib
import contextvars
import hashlib
import json
import os
import re
import shutil
import stat
import sys
import tempfile
import time
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


def output_name(name) -> str:
    """The entry of an output folder that a name (a problem's, a variant's, a method's)
    is written under: every character but ASCII letters, digits, `_`, `-`, `+` and `=`
    becomes `_` (`I.1` is `I_1`; `a/b`, `..` and `/abs` stay one plain entry inside the
    folder). **Raises:** `ValueError` for a name with none of those characters."""
    text = re.sub(r"[^A-Za-z0-9_+=-]", "_", str(name))
    if not text.strip("_"):
        raise ValueError(f"{name!r} makes no output folder name (no letter or digit)")
    return text


_DIRECT: contextvars.ContextVar[tuple[Path, set, set, Path] | None] = contextvars.ContextVar(
    "visjax_direct_outputs", default=None
)
MANIFEST = ".visjax-outputs.json"  # in an output folder: the entries a command wrote there
_LOCK = ".visjax.lock"
_STAGE_PREFIX = ".visjax-stage-"


class OutputConflictError(ValueError):
    """An output folder or file that a command may not write (a clear message says why)."""


def _read_manifest(path: Path) -> dict | None:
    try:
        m = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if not (isinstance(m, dict) and isinstance(m.get("entries"), list)):
        return None
    return m


def _plain_name(name) -> bool:
    """A name a manifest may list: one entry of the output folder itself (not `.`, `..`,
    a path, or one of visjax's own bookkeeping files)."""
    return (
        isinstance(name, str)
        and name not in ("", ".", "..")
        and not any(c in name for c in "/\\\0")
        and not name.startswith((_STAGE_PREFIX, ".visjax-outputs", ".visjax-direct"))
        and not name.endswith(".lock")
    )


def fingerprint(path) -> str:
    """A digest of an output entry as it is on disk: for a file its size and modification
    time (nanoseconds), for a folder those of every file under it with their relative
    names, for a symbolic link its target (never followed). An entry that the user
    changed, replaced or made, or that another folder's manifest names, does not match
    the fingerprint recorded when the command wrote it."""
    digest = hashlib.sha256()

    def add(p: str, rel: str) -> None:
        st = os.lstat(p)
        if stat.S_ISLNK(st.st_mode):
            digest.update(f"l {rel} {os.readlink(p)}\n".encode("utf-8", "surrogateescape"))
        elif stat.S_ISDIR(st.st_mode):
            digest.update(f"d {rel}\n".encode("utf-8", "surrogateescape"))
            for child in sorted(os.listdir(p)):
                add(os.path.join(p, child), f"{rel}/{child}")
        else:
            line = f"f {rel} {st.st_size} {st.st_mtime_ns} {stat.S_IFMT(st.st_mode)}\n"
            digest.update(line.encode("utf-8", "surrogateescape"))

    add(str(path), ".")
    return digest.hexdigest()[:32]


def _exists(path: Path) -> bool:
    return path.exists() or path.is_symlink()


def _verified(final: Path, manifest: dict) -> tuple[list[str], list[str]]:
    """The entries of an earlier run's manifest that are still what that run wrote (a
    plain name, its recorded fingerprint matching), and those that are not (an entry the
    manifest cannot vouch for: a path, `..`, no fingerprint, changed since): only the
    first may be replaced or removed."""
    prints = manifest.get("fingerprints")
    prints = prints if isinstance(prints, dict) else {}
    ours, not_ours = [], []
    for name in manifest["entries"]:
        if not _plain_name(name):
            not_ours.append(str(name))
        elif not _exists(final / name):
            continue
        elif isinstance(prints.get(name), str) and prints[name] == fingerprint(final / name):
            ours.append(name)
        else:
            not_ours.append(name)
    return ours, not_ours


def _read_journal(final: Path) -> set[str]:
    """The entries visjax wrote straight into `final` in a run that did not finish (a
    sweep's parts: `written_directly`), from its `.visjax-direct*.json` journals."""
    names: set[str] = set()
    for path in final.glob(".visjax-direct*.json"):
        names |= _read_journal_file(path)
    return names


@contextlib.contextmanager
def _locked(lock: Path, what: str):
    """An exclusive lock on `lock` (a file, created; removed on exit) for the block;
    `OutputConflictError` if another process holds it. The lock is the kernel's (`flock`):
    a process that dies, even by SIGKILL, releases it."""
    import fcntl

    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            raise OutputConflictError(
                f"{what} is being written by another visjax run; wait for it to end, or "
                "choose another --out"
            ) from None
        try:  # the file we locked is still the one at the path (not one just removed)
            same = os.stat(lock).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        yield
    finally:
        with contextlib.suppress(OSError):
            os.unlink(lock)
        os.close(fd)


def _move(source: Path, destination: Path) -> None:
    """`source` to `destination`; a folder into an existing folder (one the command wrote
    straight into the final folder, `written_directly`) entry by entry."""
    if source.is_dir() and destination.is_dir() and not destination.is_symlink():
        for item in source.iterdir():
            _move(item, destination / item.name)
        return
    if destination.is_dir() and not destination.is_symlink():
        shutil.rmtree(destination)
    os.replace(source, destination)


def _remove(path: Path) -> None:
    """An entry this command wrote (verified by `_verified`): a folder whole, a file or a
    link itself (a link is never followed)."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif _exists(path):
        path.unlink()


@contextlib.contextmanager
def staged_output(
    final,
    *,
    file: bool = False,
    command: str | None = None,
    force: bool = False,
    slot: str | None = None,
):
    """Stage an output folder (or, with `file=True`, one output file) and move it into place
    when the block exits without an exception; on an exception (a failure, SIGINT, SIGTERM
    turned into one) nothing is moved and the staging folder is removed.

    The folder is the command's, shared with the user's own files: the command writes only
    its own entries into it and records them in `.visjax-outputs.json`, each with its
    `fingerprint` (sizes and modification times); it never deletes or replaces an entry it
    did not write. The same command run again replaces its earlier entries whole (an entry
    of the earlier run that this one does not write is removed), but only those that are
    plain names of the folder and still match their fingerprints: a manifest copied,
    edited or left by anyone else names nothing that is removed, and an entry the user
    changed since is left as it is (a note says so; a new output of that name is then
    kept aside, as for any entry the command did not write);
    another command's results are refused unless `force`, which replaces them whole. A
    lock (`.visjax.lock`, the kernel's `flock`) refuses a second run into the same folder
    while one is writing. An output file that exists is replaced only with `force`.

    **Arguments:**

    - `final`: the folder (or file) the user asked for; made if missing (and removed again
        if the command fails and it is still empty).
    - `file`: stage one file instead of a folder.
    - `command`: the name recorded in the folder's manifest (e.g. `"compare"`).
    - `force`: replace another command's results (or an existing output file).
    - `slot`: one of several runs that write into the same folder at once by design (a
        sweep's `--shard i/N` slices of a job array): its own lock and its own manifest
        (`.visjax-outputs-SLOT.json`), and no earlier entry is removed (the other slices'
        parts stay; `visjax merge` assembles them).

    **Raises:** `OutputConflictError` (a `ValueError`) before any work for another
    command's results without `force`, an existing file without `force`, or a folder that
    another run holds; and at the end, before anything is moved, when an entry the command
    wrote has the name of one it did not write there (the results are then kept in a
    visible `visjax-results-*` folder inside `final`, and the error says where).

    **Yields:** the path to write to (a hidden `.visjax-stage-*` folder inside `final`, or
    beside the file). Inside the block, `sys.stdout` names `final` where the staging path
    is printed, and `visjax.io.write_summary` records `final` in place of the staging path.
    """
    final = Path(final)
    folder = final.parent if file else final
    made = []
    probe = folder
    while not probe.exists():
        made.append(probe)
        probe = probe.parent
    folder.mkdir(parents=True, exist_ok=True)
    lock = folder / (f".{final.name}{_LOCK}" if file else f".visjax-{slot}.lock" if slot else _LOCK)
    try:
        with _locked(lock, f"--out {final}"):
            # staging folders of a run killed by SIGKILL (the lock says none is running)
            pattern = f"{_STAGE_PREFIX}{final.name}-*" if file else f"{_STAGE_PREFIX}*"
            for stale in [] if slot else folder.glob(pattern):
                if stale.is_dir() and not stale.is_symlink():
                    shutil.rmtree(stale, ignore_errors=True)
            if file:
                if final.exists() and not force:
                    raise OutputConflictError(
                        f"--out {final} exists: --force to replace it, or choose another file"
                    )
                with _staging(folder, f"{final.name}-") as staging:
                    target = staging / final.name
                    with _renaming(target, final):
                        yield target
                    os.replace(target, final)
                return
            earlier: list[str] = []  # the earlier run's entries, still as it wrote them
            names = [MANIFEST] + sorted(p.name for p in final.glob(".visjax-outputs-*.json"))
            for name in names:  # the folder's manifest, and those of a job's slices
                manifest = _read_manifest(final / name)
                if manifest is None:
                    continue
                if manifest.get("command") != command and not force:
                    raise OutputConflictError(
                        f"--out {final} holds the results of `visjax {manifest.get('command')}`"
                        f" (its {name}): --force to replace them, or choose another folder"
                    )
                ours, not_ours = _verified(final, manifest)
                earlier += ours
                if not_ours:
                    shown = ", ".join(repr(n) for n in not_ours[:3])
                    sys.stderr.write(
                        f"visjax: note: --out {final}: {name} lists {shown}"
                        f"{' ...' if len(not_ours) > 3 else ''}, which this command did not "
                        "write as it is now (changed since, or not a plain name of --out): "
                        "left as it is\n"
                    )
                if slot is None:
                    earlier.append(name)  # replaced whole: the manifest goes too
            record_at = MANIFEST if slot is None else f".visjax-outputs-{slot}.json"
            journal = final / (
                ".visjax-direct.json" if slot is None else f".visjax-direct-{slot}.json"
            )
            special = {record_at, _LOCK}
            direct: set[str] = set()
            allowed = set(earlier) | _read_journal(final)
            with _staging(final, "") as staging:
                token = _DIRECT.set((final, direct, allowed, journal))
                try:
                    with _renaming(staging, final):
                        yield staging
                finally:
                    _DIRECT.reset(token)
                produced = sorted(p.name for p in staging.iterdir())
                owned = set(earlier) | direct
                clash = [n for n in produced if _exists(final / n) and n not in owned]
                if clash:
                    keep = final / f"visjax-results-{time.strftime('%Y%m%d-%H%M%S')}"
                    os.replace(staging, keep)
                    raise OutputConflictError(
                        f"--out {final}: {clash[0]!r} is not from this command's earlier run "
                        f"(not in {MANIFEST}, or changed since); nothing there was replaced, "
                        f"the results are in {keep}"
                    )
                for name in [] if slot else earlier:  # the earlier run's: replaced whole
                    if name not in special and name not in direct:
                        _remove(final / name)
                for name in produced:
                    _move(staging / name, final / name)
            entries = sorted(direct | set(produced))
            record = {
                "command": command,
                "entries": entries,
                "fingerprints": {n: fingerprint(final / n) for n in entries if _exists(final / n)},
                "written_utc": _now(),
            }
            (final / record_at).write_text(json.dumps(record, indent=1) + "\n")
            journal.unlink(missing_ok=True)
    except BaseException:
        for path in made:  # folders this call made, still empty: removed again
            with contextlib.suppress(OSError):
                path.rmdir()
        raise


def written_directly(path) -> None:
    """Record that the command writes `path` (an entry of its final output folder, e.g. a
    sweep's parts, written as they finish) straight into the final folder, not into the
    staging one: it is then the command's own in the folder's manifest, and not removed
    as an earlier run's entry. Outside `staged_output`, or for a path elsewhere, nothing.

    **Raises:** `OutputConflictError` when the entry exists and is not the command's own
    (not in the manifest of its earlier run, changed since, or a symbolic link): visjax
    never writes into a folder it did not make. The entry is recorded at once (in
    `.visjax-direct.json`), so that a run that is interrupted and then resumed may write
    into it again."""
    state = _DIRECT.get()
    if state is None:
        return
    final, direct, allowed, journal = state
    try:
        relative = Path(path).relative_to(final)
    except ValueError:
        return
    if not relative.parts:
        return
    name = relative.parts[0]
    if name in direct:
        return
    entry = final / name
    if entry.is_symlink() or (_exists(entry) and name not in allowed):
        raise OutputConflictError(
            f"--out {final}: {name!r} is not from this command's earlier run (not in "
            f"{MANIFEST}, changed since{', a symbolic link' if entry.is_symlink() else ''}); "
            "visjax writes into no folder it did not make: move it away, or choose another "
            "--out"
        )
    direct.add(name)
    listed = sorted(_read_journal_file(journal) | direct)
    tmp = journal.with_name(journal.name + ".tmp")
    tmp.write_text(json.dumps(listed) + "\n")
    os.replace(tmp, journal)


def _read_journal_file(path: Path) -> set[str]:
    try:
        listed = json.loads(path.read_text())
    except (OSError, ValueError):
        return set()
    return {n for n in listed if _plain_name(n)} if isinstance(listed, list) else set()


def _now() -> str:
    import datetime

    return datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")


@contextlib.contextmanager
def _staging(parent: Path, tag: str):
    staging = Path(tempfile.mkdtemp(prefix=f"{_STAGE_PREFIX}{tag}", dir=parent))
    try:
        yield staging
    finally:
        shutil.rmtree(staging, ignore_errors=True)


@contextlib.contextmanager
def _renaming(target: Path, final: Path):
    token = _STAGED.set((str(target), str(final)))
    stdout = sys.stdout
    sys.stdout = _Renaming(stdout)
    try:
        yield
    finally:
        sys.stdout = stdout
        _STAGED.reset(token)
