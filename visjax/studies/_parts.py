"""A sweep's results on disk as they finish: one Parquet part per chunk and a manifest of
what is done, so that an interrupted sweep loses at most the chunk in flight, a resumed one
skips what is done, and the slices of a sweep run on several machines (`--shard i/N`)
merge into one table.

The folder holds `manifest.json` (the sweep's identity, its size and chunking, the shard,
the chunks done and each part's SHA-256) and `part-<chunk>.parquet` (the rows of one chunk,
its Parquet metadata naming the sweep's identity, the chunk and its run range). Every file
is written to a temporary name and renamed into place, so a part is either whole or absent,
and the manifest never names a part that is not on disk. A part is used only when it is
verified (`verify_part`): its checksum the manifest's, its metadata this sweep's and this
chunk's, its runs exactly the chunk's; a resumed sweep recomputes any other, `merge_parts`
refuses it, naming it.
"""

import contextlib
import hashlib
import json
import os
import re
import tempfile
from collections.abc import Iterable, Sequence
from pathlib import Path

from ..io import user_path, written_directly

MANIFEST = "manifest.json"
_VERSION = 2  # 2: each part's checksum in the manifest, its identity in its metadata
_META = b"visjax.part"  # a part's Parquet key-value metadata: identity, chunk, runs


class PartsError(ValueError):
    """A parts folder that cannot be used as asked (another sweep's, missing or duplicated
    runs): the message says what and why."""


def part_name(chunk: int) -> str:
    return f"part-{chunk:07d}.parquet"


def _atomic_write(path: Path, write) -> None:
    """`write(tmp_path)` then rename onto `path` (same folder: an atomic replace)."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    os.close(fd)
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_json(path: Path, data: dict) -> None:
    def write(tmp):
        with open(tmp, "w") as f:
            json.dump(data, f, indent=1, sort_keys=True)

    _atomic_write(Path(path), write)


class Parts:
    """The parts folder of one sweep (or one shard of it).

    `identity`: a digest of what the sweep computes (the problem or function, the method
    and fixed parameters, the parameter points, the seeds, the chunk size): parts of
    different sweeps never mix. `n_runs`, `chunk`: the runs and the chunk size (chunk `c`
    holds runs `c * chunk` to `(c + 1) * chunk - 1`). `shard`: `(i, n)` or `None`.
    """

    def __init__(self, folder, identity: str, n_runs: int, chunk: int, shard=None, info=None):
        self.folder = Path(folder)
        self.identity, self.n_runs, self.chunk = identity, int(n_runs), int(chunk)
        self.shard = None if shard is None else (int(shard[0]), int(shard[1]))
        self.info = dict(info or {})
        self.done: set[int] = set()
        self.checksums: dict[int, str] = {}

    @property
    def n_chunks(self) -> int:
        return -(-self.n_runs // self.chunk)

    def chunks(self) -> list[int]:
        """This sweep's (or shard's) chunks: all, or every `n`-th from `i`."""
        if self.shard is None:
            return list(range(self.n_chunks))
        i, n = self.shard
        return list(range(i, self.n_chunks, n))

    def _manifest(self) -> dict:
        return {
            "version": _VERSION,
            "identity": self.identity,
            "n_runs": self.n_runs,
            "chunk": self.chunk,
            "n_chunks": self.n_chunks,
            "shard": None if self.shard is None else list(self.shard),
            "done": sorted(self.done),
            "checksums": {str(c): self.checksums[c] for c in sorted(self.done)},
            "info": self.info,
        }

    def open(self, *, resume: bool, log=None) -> set[int]:
        """Create the folder, or reopen it with `resume=True`. **Returns:** the chunks
        already done, each verified (`verify_part`): a part that is truncated, altered
        since it was written, or another sweep's is left out (recomputed by the sweep;
        `log` says which and why). **Raises:** `PartsError` for a folder that holds another
        sweep's parts, any parts without `resume`, or a manifest that cannot be read."""
        path = self.folder / MANIFEST
        self.checksums: dict[int, str] = {}
        if self.folder.is_symlink() or (self.folder.exists() and not self.folder.is_dir()):
            raise PartsError(
                f"{self.folder} is a symbolic link or a file: a sweep writes its parts only "
                "into a folder of its own; choose another folder"
            )
        if path.exists():
            old = read_manifest(self.folder)
            if old["identity"] != self.identity or old["chunk"] != self.chunk:
                raise PartsError(
                    f"{self.folder} holds the parts of a different sweep (other parameter "
                    "points, seeds, problem or chunk size); choose another folder, or remove "
                    "it (`--force` on the command line) to start over."
                )
            if old["shard"] != (None if self.shard is None else list(self.shard)):
                raise PartsError(
                    f"{self.folder} holds the parts of shard {old['shard']}, not {self.shard}."
                )
            listed = [c for c in old["done"] if (self.folder / part_name(c)).exists()]
            if listed and not resume:
                raise PartsError(
                    f"{self.folder} already holds {len(listed)} finished chunk(s) of this "
                    "sweep: resume it (`resume=True`, `--resume`) or remove it (`--force`) to "
                    "start over."
                )
            done = set()
            for c in listed if resume else ():
                problem = verify_part(self.folder, old, c)
                if problem is None:
                    done.add(c)
                    self.checksums[c] = old["checksums"][str(c)]
                elif log is not None:
                    log(f"{self.folder / part_name(c)}: {problem}; recomputed")
            self.done = done
        else:
            self.folder.mkdir(parents=True, exist_ok=True)
        write_json(path, self._manifest())
        return set(self.done)

    def write(self, chunk: int, frame) -> None:
        """Write chunk `chunk`'s rows (a DataFrame) as its part (its metadata naming the
        sweep, the chunk and its runs), then mark it done with its checksum."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        first = int(chunk) * self.chunk
        runs = [first, min(first + self.chunk, self.n_runs) - 1]
        table = pa.Table.from_pandas(frame, preserve_index=False)
        meta = {"identity": self.identity, "chunk": int(chunk), "runs": runs}
        table = table.replace_schema_metadata(
            {**(table.schema.metadata or {}), _META: json.dumps(meta).encode()}
        )
        path = self.folder / part_name(chunk)
        _atomic_write(path, lambda tmp: pq.write_table(table, tmp))
        self.checksums[int(chunk)] = _sha256(path)
        self.done.add(int(chunk))
        write_json(self.folder / MANIFEST, self._manifest())

    def read(self, chunk: int):
        import pandas as pd

        return pd.read_parquet(self.folder / part_name(chunk))

    def runs_done(self) -> int:
        return sum(min(self.chunk, self.n_runs - c * self.chunk) for c in self.done)


_OWN = re.compile(r"(\.)?(part-\d{7}\.parquet|manifest\.json)(?(1)\..+|)")  # and temporaries


def clear_parts(folder) -> None:
    """Remove a sweep's parts from `folder` (to start over): only what a sweep writes there
    (its `part-*.parquet`, its `manifest.json` and their temporary files), then the folder
    itself if it is left empty. Anything else in it stays; a symbolic link is never
    followed. **Raises:** `PartsError` for a link or a file where the folder should be."""
    folder = Path(folder)
    if folder.is_symlink():
        raise PartsError(
            f"{folder} is a symbolic link: visjax clears no parts through a link; remove the "
            "link, or choose another --out"
        )
    if not folder.exists():
        return
    if not folder.is_dir():
        raise PartsError(f"{folder} is a file, not a sweep's parts folder")
    for path in folder.iterdir():
        if _OWN.fullmatch(path.name) and path.is_file() and not path.is_symlink():
            path.unlink()
    with contextlib.suppress(OSError):
        folder.rmdir()


def sweep_parts(folder, shard=None, *, resume=False, force=False) -> Path:
    """Where a sweep writing into the output folder `folder` keeps its parts: `parts/`, or
    `parts-i-of-N/` for the slice `shard=(i, N)`, in the folder the user asked for (never a
    staging one, `visjax.io.staged_output`: an interrupted sweep keeps them), recorded as
    the command's own entry of it. `force` clears them (a fresh start). **Raises:**
    `ValueError` when `folder` holds a finished sweep (its `summary.json`) and neither
    `resume` nor `force` is given."""
    final = Path(user_path(str(folder)))
    parts = final / ("parts" if shard is None else f"parts-{shard[0]}-of-{shard[1]}")
    written_directly(parts)  # the command's own entry of --out (its manifest)
    if force:
        clear_parts(parts)  # only what a sweep wrote there; a link is never followed
        return parts
    try:
        kind = None if resume else json.loads((final / "summary.json").read_text()).get("kind")
    except (ValueError, OSError):
        kind = None
    if kind == "sweep":
        raise ValueError(
            f"{final} holds a finished sweep: --force to replace it, or --resume to rebuild "
            "its table from its parts"
        )
    return parts


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _int(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def read_manifest(folder) -> dict:
    """A parts folder's manifest, checked: every key a sweep writes, of its type.
    **Raises:** `PartsError` naming the file and what is wrong (missing, not JSON, a key
    missing or of the wrong type), and what to do."""
    path = Path(folder) / MANIFEST
    if not path.exists():
        raise PartsError(f"{folder}: no {MANIFEST} (not a sweep's parts folder).")
    fix = f"delete {folder} (or run the sweep with --force) to start over"
    try:
        m = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError) as e:
        raise PartsError(f"{path}: cannot be read ({e}); {fix}.") from None
    except ValueError as e:
        raise PartsError(f"{path}: not valid JSON ({e}); {fix}.") from None
    if not isinstance(m, dict):
        raise PartsError(f"{path}: not a sweep's manifest (a JSON object); {fix}.")
    if m.get("version") == 1:
        m.setdefault("checksums", None)  # written before parts carried checksums
    kinds = {
        "identity": lambda x: isinstance(x, str),
        "n_runs": lambda x: _int(x) and x >= 0,
        "chunk": lambda x: _int(x) and x >= 1,
        "n_chunks": lambda x: _int(x) and x >= 0,
        "shard": lambda x: x is None or (isinstance(x, list) and len(x) == 2),
        "done": lambda x: isinstance(x, list) and all(_int(c) and c >= 0 for c in x),
        "checksums": lambda x: x is None or isinstance(x, dict),
    }
    for key, ok in kinds.items():
        if key not in m:
            raise PartsError(f"{path}: no {key!r} (not a sweep's manifest, or damaged); {fix}.")
        if not ok(m[key]):
            raise PartsError(f"{path}: {key!r} is {m[key]!r}, not a sweep's value; {fix}.")
    if m["n_chunks"] != -(-m["n_runs"] // m["chunk"]) or any(c >= m["n_chunks"] for c in m["done"]):
        raise PartsError(f"{path}: its chunks do not add up to its runs (edited?); {fix}.")
    m.setdefault("info", {})
    return m


def saved_runs(folder) -> tuple[int, int]:
    """`(done, total)`: the runs whose chunks a sweep's parts folder holds, of all its runs
    (`(0, 0)` where there is no readable manifest): what an interrupted sweep kept."""
    try:
        m = read_manifest(folder)
    except ValueError:
        return 0, 0
    n, chunk = m["n_runs"], m["chunk"]
    return sum(min(chunk, n - c * chunk) for c in m["done"]), n


def verify_part(folder, manifest: dict, chunk: int) -> str | None:
    """Whether `folder`'s part of chunk `chunk` is the one its sweep wrote. **Returns:**
    `None` for a verified part; otherwise why not: missing, its SHA-256 not the manifest's
    (truncated, edited, or another part copied over it), unreadable, its metadata another
    sweep's or another chunk's, or its runs not exactly the chunk's."""
    import pyarrow.parquet as pq

    path = Path(folder) / part_name(chunk)
    if not path.is_file():
        return "missing"
    recorded = (manifest.get("checksums") or {}).get(str(chunk))
    if recorded is None:
        return "no checksum in the manifest (written by an older visjax)"
    if _sha256(path) != recorded:
        return "its checksum differs from the manifest's (truncated, altered or replaced)"
    try:
        table = pq.read_table(path)
    except Exception as e:  # pyarrow's own errors: a damaged file
        return f"not a readable Parquet part ({type(e).__name__})"
    try:
        meta = json.loads((table.schema.metadata or {})[_META])
    except (KeyError, ValueError):
        return "no sweep metadata (not a part a sweep wrote)"
    first = chunk * manifest["chunk"]
    runs = [first, min(first + manifest["chunk"], manifest["n_runs"]) - 1]
    if meta.get("identity") != manifest["identity"]:
        return "the part of another sweep"
    if meta.get("chunk") != chunk or meta.get("runs") != runs:
        return f"the part of chunk {meta.get('chunk')}, not {chunk}"
    if "run" not in table.column_names:
        return "no run column"
    values = table.column("run").to_pylist()
    if values != list(range(runs[0], runs[1] + 1)):
        return f"its rows are not runs {runs[0]} to {runs[1]}"
    return None


def find_parts(paths: Iterable) -> list[Path]:
    """The parts folders (folders with a manifest) in or under `paths`."""
    found = []
    for p in paths:
        p = Path(p)
        if not p.exists():
            raise PartsError(f"{p}: no such folder.")
        if (p / MANIFEST).exists():
            found.append(p)
        found.extend(sorted(m.parent for m in p.rglob(MANIFEST) if m.parent != p))
    if not found:
        raise PartsError(f"no sweep parts (no {MANIFEST}) in {[str(p) for p in paths]}.")
    return sorted(set(found))


def merge_parts(folders: Sequence) -> tuple:
    """One table from the parts of one sweep spread over `folders` (its shards, or an
    interrupted run and its resumption). **Returns:** `(table, manifest)`, the rows sorted
    by run. **Raises:** `PartsError` for parts of different sweeps, a run found twice, or
    runs missing (naming the chunks)."""
    import pandas as pd

    manifests = [(f, read_manifest(f)) for f in folders]
    first = manifests[0][1]
    for f, m in manifests[1:]:
        if (m["identity"], m["chunk"], m["n_runs"]) != (
            first["identity"],
            first["chunk"],
            first["n_runs"],
        ):
            raise PartsError(
                f"{f} holds the parts of a different sweep than {manifests[0][0]}: they do "
                "not merge."
            )
    owner: dict[int, Path] = {}
    frames = []
    for f, m in manifests:
        for c in m["done"]:
            if not (Path(f) / part_name(c)).exists():
                continue
            problem = verify_part(f, m, c)
            if problem is not None:
                raise PartsError(
                    f"{Path(f) / part_name(c)}: {problem}: resume the sweep that wrote it "
                    "(--resume, which recomputes it) or delete the part, then merge again."
                )
            if c in owner:
                raise PartsError(
                    f"chunk {c} (runs {c * first['chunk']} to "
                    f"{min((c + 1) * first['chunk'], first['n_runs']) - 1}) is in both "
                    f"{owner[c]} and {f}: a run found twice."
                )
            owner[c] = Path(f)
            frames.append(pd.read_parquet(Path(f) / part_name(c)))
    missing = sorted(set(range(first["n_chunks"])) - set(owner))
    if missing:
        shown = ", ".join(map(str, missing[:10])) + (" ..." if len(missing) > 10 else "")
        raise PartsError(
            f"{len(missing)} of {first['n_chunks']} chunks are missing (chunks {shown}): "
            "run the shards that hold them (or resume the interrupted one) before merging."
        )
    table = pd.concat(frames, ignore_index=True).sort_values("run", kind="stable")
    table = table.reset_index(drop=True)
    if len(table) != first["n_runs"] or table["run"].duplicated().any():
        raise PartsError(f"the parts hold {len(table)} rows for {first['n_runs']} runs.")
    return table, first


def merge_sweeps(paths: Iterable) -> dict:
    """The parts found in or under each of `paths` (`find_parts`), grouped by the sweep
    they belong to (their manifests' identity) and merged (`merge_parts`): one sweep's
    shards, or the sweeps of a problem's variants. **Returns:** tag -> `(table, manifest,
    folders)`, the tag `None` for a single sweep, else the name of the folder holding its
    parts (a variant's; made unique with the identity's start where two agree)."""
    groups: dict[str, list] = {}
    for folder in find_parts(paths):
        groups.setdefault(read_manifest(folder)["identity"], []).append(folder)
    out: dict = {}
    for identity, members in groups.items():
        table, manifest = merge_parts(members)
        tag = Path(members[0]).parent.name if len(groups) > 1 else None
        if tag is not None and tag in out:
            tag = f"{tag}_{identity[:8]}"
        out[tag] = (table, manifest, members)
    return out
