"""Append-only storage of a dataset's tables: immutable Parquet part files listed by an atomically replaced manifest.

Layout, inside the dataset directory (docs/sweeps.md, "Storage"):

- ``manifest.json``: ``{"format", "next_id", "parts": [{"id", "level", "tables": {name: {"file", "rows",
  "sha256"}}}, ...]}``, the parts in recording order. The manifest is the commit point: a part belongs to the
  dataset once a manifest naming it has been renamed into place. Files it does not name (left by a write that a
  crash interrupted, or by a merge not yet cleaned up) are ignored by readers and removed by the next writer.
  No manifest: no parts.
- ``parts/<id>.<table>.parquet``: rows of one or more appends, Parquet with page checksums.

Appending writes the new part's files (each fsync'ed), then the manifest (`write_atomic`: a temporary sibling,
fsync, rename, fsync of the directory), so the cost of an append does not grow with what is already stored and a
crash at any moment leaves the previous manifest and every file it names. To keep the number of files small, when
the last `FANOUT` parts have one level they are merged into one part of the next level (tiered compaction, up to
`MAX_LEVEL`: each row is rewritten at most `MAX_LEVEL` times and a part holds at most ``FANOUT**MAX_LEVEL``
appends); the merged files are removed once the manifest no longer names them.

Reading checks every file against the manifest (SHA-256, row count) and the Parquet page checksums, and conforms
it to the table's schema (columns a part predates read as null); a file that fails raises `PartDamaged` naming it.

The JSON documents (the manifest here, ``metadata.json`` in `uwlab.experiments.dataset`) are sealed: each carries
the SHA-256 of its own canonical JSON (key `SEAL_KEY`) and is written twice, the file and its backup copy
(`backup_path`: ``manifest.backup.json``), each atomically. `read_sealed` reads both and takes the first copy whose
seal holds, reporting a damaged or missing other copy (`uwlab dataset check` names it, --repair rewrites it), so
any single damaged byte of either copy is either repaired from the other or (both damaged) refused — never read as
another value. A dataset written before seals (no backup copies) is read as it is.
Files are created with the user's umask (lab data is shared). A failed write (disk full, read-only) raises
`DatasetWriteError`; the previous state stays intact.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import secrets
from dataclasses import asdict, dataclass, field
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from uwlab.errors import ConfigError, UwlabError
from uwlab.model.data import MAX_BINARY_BYTES, MAX_JSON_BYTES, read_bytes
from uwlab.outputs import MANIFEST_FILE

FORMAT = "uwlab-dataset-parts/1"
PARTS_DIR = "parts"
FANOUT = 16
MAX_LEVEL = 3
TMP_MARK = ".tmp-"
READ_RETRIES = 5


class DatasetWriteError(UwlabError):
    """Writing to the dataset failed (disk full, permissions, read-only); everything recorded before is intact."""


class PartDamaged(UwlabError):
    """A part file is missing, unreadable or disagrees with the manifest (checksum, rows, schema)."""

    def __init__(self, root: Path, file: str, reason: str):
        self.file = file
        self.reason = reason
        super().__init__(
            f"dataset {root}: {file} is damaged ({reason}); run `uwlab dataset check {root}` "
            "(--repair sets the damaged points aside; --resume then measures them again)"
        )


class ManifestDamaged(UwlabError):
    """The manifest is unreadable or not a manifest: the dataset cannot be read."""


SEAL_KEY = "_sha256"


def backup_path(path: Path) -> Path:
    """The backup copy of a sealed document: ``manifest.json`` → ``manifest.backup.json``."""
    return path.with_name(f"{path.stem}.backup{path.suffix}")


def _digest(document: dict) -> str:
    canonical = json.dumps(document, sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False)
    return hashlib.sha256(canonical.encode()).hexdigest()


def write_sealed(path: Path, document: dict, indent: int | None = None) -> None:
    """Write ``document`` (plain JSON values) with its seal to ``path``, then to its backup copy (each with
    `write_atomic`): a crash between the two leaves two valid copies, the file one state newer."""
    body = {**document, SEAL_KEY: _digest(document)}
    text = json.dumps(
        body, indent=indent, separators=None if indent else (",", ":"), ensure_ascii=False, allow_nan=False
    )
    data = (text + "\n").encode()
    write_atomic(path, data)
    write_atomic(backup_path(path), data)


def _read_copy(path: Path) -> tuple[dict, bool]:
    """One copy of a sealed document and whether it carries a seal; `ValueError` saying why it cannot be trusted
    (`FileNotFoundError` if it does not exist). Read as every input is (`uwlab.model.data.read_bytes`: a regular
    file, bounded)."""
    if not os.path.lexists(path):
        raise FileNotFoundError(errno.ENOENT, "no such file", str(path))
    try:
        data = read_bytes(path, path.name, MAX_JSON_BYTES, "JSON")
    except ConfigError as exc:
        raise ValueError(exc.reason) from None
    document = json.loads(data.decode("utf-8"))
    if not isinstance(document, dict):
        raise ValueError("not a JSON object")
    seal = document.pop(SEAL_KEY, None)
    if seal is not None and seal != _digest(document):
        raise ValueError("its content differs from its checksum")
    return document, seal is not None


@dataclass(frozen=True)
class SealedRead:
    """A sealed document as read: the ``document``, the copy it came from and what is wrong with the copies."""

    document: dict
    source: Path
    problems: tuple[str, ...] = ()


def read_sealed(path: Path) -> SealedRead:
    """The document at ``path`` from the first of its copies whose seal holds (`write_sealed`), and what is wrong
    with either copy: both are read every time, so a damaged or missing backup is reported while the file still
    holds (and a repair can rewrite it). An unsealed file without a backup copy is a document written before seals
    and is taken as it is. `FileNotFoundError` when neither copy exists; `ValueError` naming both problems when
    neither can be trusted."""
    backup = backup_path(path)
    problems: list[str] = []
    found: list[tuple[Path, dict, bool]] = []
    missing = []
    for copy in (path, backup):
        try:
            document, sealed = _read_copy(copy)
        except FileNotFoundError:
            missing.append(copy)
            continue
        except (OSError, ValueError) as exc:
            problems.append(f"{copy.name} is damaged ({exc})")
            continue
        if copy == backup and not sealed:
            problems.append(f"{copy.name} is damaged (its checksum is missing)")
            continue
        found.append((copy, document, sealed))
    if len(missing) == 2:
        raise FileNotFoundError(errno.ENOENT, "no such file", str(path))
    if found and found[0][0] == path and backup in missing and not found[0][2]:
        return SealedRead(found[0][1], path)  # written before seals: one unsealed copy
    if found and found[0][0] == path and not found[0][2]:
        problems.insert(0, f"{path.name} is damaged (its checksum is missing)")
        found = found[1:]
    problems[len(problems) :] = [f"{copy.name} is missing" for copy in missing]
    if not found:
        raise ValueError("; ".join(problems))
    return SealedRead(found[0][1], found[0][0], tuple(problems))


@dataclass(frozen=True)
class PartFile:
    file: str
    rows: int
    sha256: str


@dataclass(frozen=True)
class Part:
    id: int
    level: int
    tables: dict[str, PartFile] = field(default_factory=dict)

    def rows(self, name: str) -> int:
        return self.tables[name].rows if name in self.tables else 0


def write_atomic(path: Path, data: bytes) -> None:
    """Replace ``path`` by ``data`` atomically and durably: a temporary sibling (user's umask), fsync, rename,
    fsync of the directory. `DatasetWriteError` on failure, with ``path`` untouched and no temporary left."""
    tmp = path.with_name(f".{path.name}{TMP_MARK}{os.getpid()}-{secrets.token_hex(4)}")
    try:
        write_durable(tmp, data)
        os.replace(tmp, path)
        fsync_directory(path.parent)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise _write_error(path, exc) from exc
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_durable(path: Path, data: bytes) -> None:
    """Create or truncate ``path`` (user's umask), write ``data`` and fsync it (no rename: for new, unnamed files)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_CLOEXEC, 0o666)
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view) :]
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_directory(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _write_error(path: Path, exc: OSError) -> DatasetWriteError:
    return DatasetWriteError(
        f"dataset {path.parent}: cannot write {path.name} ({exc.strerror or exc}); "
        "everything recorded before is intact: free space or fix permissions, then --resume"
    )


def parquet_bytes(tables: list[pa.Table], schema: pa.Schema) -> bytes:
    """One Parquet file (page checksums on) holding ``tables`` in order, one row group or more each."""
    sink = pa.BufferOutputStream()
    with pq.ParquetWriter(sink, schema, write_page_checksum=True) as writer:
        for table in tables:
            writer.write_table(table)
    return sink.getvalue().to_pybytes()


def arrow_copy(data: bytes) -> pa.Buffer:
    """A copy of ``data`` in Arrow's own memory, holding no Python object: the input to hand Arrow's threaded
    Parquet reader. Its worker threads may drop their last reference to the input after the read has returned; a
    buffer over a Python object (``pa.BufferReader(bytes)``) then takes the GIL in its destructor, and if the
    interpreter is shutting down by then the thread is ended inside that destructor and the process aborts
    ("terminate called without an active exception", SIGABRT at the exit of a command that read a dataset)."""
    sink = pa.BufferOutputStream()
    sink.write(data)
    return sink.getvalue()


def conform(table: pa.Table, schema: pa.Schema) -> pa.Table:
    """``table`` with exactly ``schema``'s columns: missing ones null (older writers), types cast when safe.
    Unknown columns or impossible casts raise `ValueError` naming the column."""
    names = table.column_names  # pyarrow builds a new list at each .column_names and .names: taken once
    expected = set(schema.names)
    unknown = [name for name in names if name not in expected]
    if unknown:
        raise ValueError(f"unknown column {unknown[0]!r}")
    present = set(names)
    columns = []
    for schema_field in schema:
        if schema_field.name not in present:
            columns.append(pa.nulls(table.num_rows, schema_field.type))
            continue
        column = table.column(schema_field.name)
        try:
            columns.append(column if column.type == schema_field.type else column.cast(schema_field.type))
        except (pa.ArrowInvalid, pa.ArrowNotImplementedError):
            raise ValueError(f"column {schema_field.name!r} is {column.type}, expected {schema_field.type}") from None
    return pa.Table.from_arrays(columns, schema=schema)


class PartStore:
    """The parts of one dataset directory. ``schemas``: the tables (name → schema); tables named in ``cached``
    are kept in memory once read or written (small ones: the points)."""

    def __init__(self, root: Path, schemas: dict[str, pa.Schema], cached: tuple[str, ...] = ()):
        self.root = Path(root)
        self.schemas = schemas
        self.cached = cached
        self.parts: list[Part] = []
        self.next_id = 1
        self.copy_problems: tuple[str, ...] = ()
        self._cache: dict[tuple[int, str], pa.Table] = {}

    @property
    def manifest_path(self) -> Path:
        return self.root / MANIFEST_FILE

    # -- the manifest ----------------------------------------------------------------------------
    def load(self) -> PartStore:
        """Read the manifest (none: no parts) from its first trustworthy copy (`read_sealed`; what was wrong with
        the other is kept in ``copy_problems``); `ManifestDamaged` if no copy can be read."""
        try:
            found = read_sealed(self.manifest_path)
        except FileNotFoundError:
            self.parts, self.next_id, self.copy_problems = [], 1, ()
            return self
        except (OSError, ValueError) as exc:
            raise ManifestDamaged(f"dataset {self.root}: unreadable {MANIFEST_FILE} ({exc})") from None
        document = found.document
        try:
            if document["format"] != FORMAT:
                raise ValueError(f"format {document['format']!r}, expected {FORMAT!r}")
            parts = [
                Part(
                    int(p["id"]),
                    int(p["level"]),
                    {
                        name: PartFile(str(f["file"]), int(f["rows"]), str(f["sha256"]))
                        for name, f in p["tables"].items()
                    },
                )
                for p in document["parts"]
            ]
            next_id = int(document["next_id"])
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise ManifestDamaged(f"dataset {self.root}: {MANIFEST_FILE} is not a parts manifest ({exc})") from None
        self.parts, self.next_id, self.copy_problems = parts, next_id, found.problems
        self._cache = {key: table for key, table in self._cache.items() if key[0] in {p.id for p in parts}}
        return self

    def reseal(self) -> None:
        """Rewrite both copies of the manifest as read (a damaged copy is replaced by the intact one)."""
        if self.manifest_path.exists() or backup_path(self.manifest_path).exists():
            self._commit(self.parts, self.next_id)

    def _commit(self, parts: list[Part], next_id: int) -> None:
        """Make ``parts`` the dataset's: their files' names durable (fsync of ``parts/``), then the manifest."""
        document = {"format": FORMAT, "next_id": next_id, "parts": [asdict(p) for p in parts]}
        if (self.root / PARTS_DIR).is_dir():
            try:
                fsync_directory(self.root / PARTS_DIR)
            except OSError as exc:
                raise _write_error(self.root / PARTS_DIR, exc) from exc
        write_sealed(self.manifest_path, document)
        self.parts, self.next_id, self.copy_problems = parts, next_id, ()

    # -- reading ----------------------------------------------------------------------------------
    def read(self, part: Part, name: str) -> pa.Table:
        """One table of one part, checked (SHA-256, Parquet page checksums, rows, schema); `PartDamaged` if not.
        A part without that table gives an empty one. `FileNotFoundError` if its file has gone (a concurrent
        writer merged it: reload and read again)."""
        key = (part.id, name)
        if key in self._cache:
            return self._cache[key]
        schema = self.schemas[name]
        entry = part.tables.get(name)
        if entry is None:
            return schema.empty_table()
        path = self.root / entry.file
        try:
            data = read_bytes(path, entry.file, MAX_BINARY_BYTES, "Parquet")
        except ConfigError as exc:
            if not os.path.lexists(path):
                raise FileNotFoundError(errno.ENOENT, "no such file", str(path)) from None
            raise PartDamaged(self.root, entry.file, exc.reason) from None
        if hashlib.sha256(data).hexdigest() != entry.sha256:
            raise PartDamaged(self.root, entry.file, "SHA-256 differs from the manifest")
        try:
            table = conform(pq.read_table(pa.BufferReader(arrow_copy(data)), page_checksum_verification=True), schema)
        except (OSError, pa.ArrowException, ValueError) as exc:
            raise PartDamaged(self.root, entry.file, f"unreadable: {exc}") from None
        if table.num_rows != entry.rows:
            raise PartDamaged(self.root, entry.file, f"{table.num_rows} rows, the manifest says {entry.rows}")
        if name in self.cached:
            self._cache[key] = table
        return table

    def read_all(self, name: str) -> pa.Table:
        """One table over all parts, in recording order (the manifest re-read if a concurrent writer merged
        parts meanwhile)."""
        for _ in range(READ_RETRIES):
            try:
                return pa.concat_tables(
                    [self.schemas[name].empty_table()] + [self.read(part, name) for part in self.parts]
                )
            except FileNotFoundError as exc:
                missing = Path(exc.filename)
                self.load()
        raise PartDamaged(self.root, missing.relative_to(self.root).as_posix(), "missing")

    # -- writing (the caller holds the dataset's lock) ---------------------------------------------
    def append(self, tables: dict[str, pa.Table]) -> Part:
        """Store ``tables`` (name → rows, with that table's schema) as a new part, then merge parts if due."""
        part = self._write_part(self.next_id, 0, {name: [table] for name, table in tables.items() if table.num_rows})
        self._commit([*self.parts, part], self.next_id + 1)
        self._cache.update({(part.id, name): table for name, table in tables.items() if name in self.cached})
        self._compact()
        return part

    def replace(self, changes: dict[int, dict[str, pa.Table] | None]) -> list[Path]:
        """Replace parts by id with new contents (None: drop the part), keeping their places and levels; returns
        the files no longer named (the caller moves them aside)."""
        parts: list[Part] = []
        next_id, dropped = self.next_id, list[Path]()
        for part in self.parts:
            if part.id not in changes:
                parts.append(part)
                continue
            dropped.extend(self.root / f.file for f in part.tables.values())
            tables = changes[part.id]
            if tables and any(t.num_rows for t in tables.values()):
                parts.append(self._write_part(next_id, part.level, {n: [t] for n, t in tables.items() if t.num_rows}))
                next_id += 1
        self._commit(parts, next_id)
        self._cache = {key: table for key, table in self._cache.items() if key[0] not in changes}
        return dropped

    def _write_part(self, part_id: int, level: int, tables: dict[str, list[pa.Table]]) -> Part:
        (self.root / PARTS_DIR).mkdir(exist_ok=True)
        files = {}
        for name, pieces in tables.items():
            relative = f"{PARTS_DIR}/{part_id:08d}.{name}.parquet"
            data = parquet_bytes(pieces, self.schemas[name])
            try:
                write_durable(self.root / relative, data)
            except OSError as exc:
                (self.root / relative).unlink(missing_ok=True)
                raise _write_error(self.root / relative, exc) from exc
            files[name] = PartFile(relative, sum(p.num_rows for p in pieces), hashlib.sha256(data).hexdigest())
        return Part(part_id, level, files)

    def _compact(self) -> None:
        """Merge the last `FANOUT` parts while they share a level below `MAX_LEVEL`."""
        while len(self.parts) >= FANOUT:
            tail = self.parts[-FANOUT:]
            level = tail[-1].level
            if level >= MAX_LEVEL or any(p.level != level for p in tail):
                return
            pieces = {n: [self.read(p, n) for p in tail if n in p.tables] for n in self.schemas}
            merged = self._write_part(self.next_id, level + 1, {n: t for n, t in pieces.items() if t})
            self._cache.update(
                {(merged.id, n): pa.concat_tables([self.schemas[n].empty_table(), *pieces[n]]) for n in self.cached}
            )
            self._commit([*self.parts[:-FANOUT], merged], self.next_id + 1)
            for part in tail:
                for name in part.tables:
                    self._cache.pop((part.id, name), None)
                    (self.root / part.tables[name].file).unlink(missing_ok=True)

    # -- files no manifest names -------------------------------------------------------------------
    def stray_files(self) -> list[Path]:
        """Files in ``parts/`` the manifest does not name, and temporary files left in the directory."""
        named = {self.root / f.file for p in self.parts for f in p.tables.values()}
        parts_dir = self.root / PARTS_DIR
        strays = [p for p in sorted(parts_dir.iterdir()) if p not in named] if parts_dir.is_dir() else []
        return strays + sorted(p for p in self.root.iterdir() if TMP_MARK in p.name and p.name.startswith("."))

    def remove_strays(self) -> None:
        for path in self.stray_files():
            path.unlink(missing_ok=True)
