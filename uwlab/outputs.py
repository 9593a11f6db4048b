"""Where outputs may go: the checks every writer makes before it measures, computes or writes anything.

A bad output path is refused up front with one `ConfigError` naming the option and the path, so that a long
sweep or fit never fails at its end and nothing is left half-written. The rules, the same for every command:

- the path is valid UTF-8 (a name that is not — e.g. Latin-1 bytes given on the command line — cannot be
  recorded in JSON metadata, so it is refused), at most ``PATH_MAX`` bytes, and no component is longer than the
  file system's ``NAME_MAX`` (255 bytes on Linux file systems);
- its parent directory exists (outputs never create missing parents) and accepts new files: a probe file is
  created and removed there, so read-only file systems, permission bits and anything else the system refuses
  are found now, whoever the user is;
- an existing file is not overwritten unless the command's replace option says so; an existing directory is
  written into only where the command says (and must then accept new files);
- nothing is written inside a uwlab dataset (a folder holding `METADATA_FILE` and `MANIFEST_FILE`): its files
  are the dataset's own, checked and repaired as a whole. The exceptions are the documented default outputs
  directly under it, `DERIVED_OUTPUTS`: ``uwlab fit DATASET``'s `FIT_FOLDER` and ``uwlab report DATASET``'s
  `REPORT_FILE` (names no dataset file ever has).

>>> output_file("/nonexistent/report.html", "--out")
Traceback (most recent call last):
...
uwlab.errors.ConfigError: --out = '/nonexistent/report.html': directory /nonexistent does not exist
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from uwlab.errors import ConfigError

PATH_MAX_BYTES = 4096
NAME_MAX_BYTES = 255
# The two files that make a folder a uwlab dataset (`uwlab.experiments.dataset`, `uwlab.experiments.dataset_store`).
METADATA_FILE = "metadata.json"
MANIFEST_FILE = "manifest.json"
FIT_FOLDER = "fit"  # uwlab fit DATASET writes to DATASET/fit by default
REPORT_FILE = "report.html"  # uwlab report DIR writes DIR/report.html by default
DERIVED_OUTPUTS = (FIT_FOLDER, REPORT_FILE)


def _name_max(path: Path) -> int:
    """NAME_MAX of the file system holding the nearest existing ancestor of `path`."""
    for directory in (path, *path.parents):
        try:
            return os.pathconf(directory, "PC_NAME_MAX")
        except (OSError, ValueError):  # missing, not a directory, or a name too long for the system
            continue
    return NAME_MAX_BYTES


def checked_name(path: str | os.PathLike, key: str) -> Path:
    """`path` as a `Path` once its name is valid UTF-8 and within the system's length limits."""
    text = os.fspath(path)
    try:
        encoded = text.encode("utf-8")
    except UnicodeEncodeError:
        raise ConfigError(key, text, "is not valid UTF-8; choose a UTF-8 name") from None
    if not text:
        raise ConfigError(key, text, "is empty")
    if len(encoded) > PATH_MAX_BYTES:
        raise ConfigError(key, f"{text[:40]}...", f"is {len(encoded)} bytes long; the limit is {PATH_MAX_BYTES}")
    path = Path(text)
    limit = _name_max(path.absolute())
    for part in path.parts:
        if len(part.encode("utf-8")) > limit:
            raise ConfigError(
                key,
                text,
                f"has a {len(part.encode('utf-8'))}-byte name ({part[:20]}...); the file system allows {limit}",
            )
    return path


def dataset_holding(path: Path) -> Path | None:
    """The uwlab dataset folder that `path` lies strictly inside, if any (links resolved)."""
    for folder in path.absolute().resolve().parents:
        if (folder / METADATA_FILE).is_file() and (folder / MANIFEST_FILE).is_file():
            return folder
    return None


def _outside_datasets(path: Path, key: str) -> None:
    dataset = dataset_holding(path)
    if dataset is not None and path.absolute().resolve().relative_to(dataset).parts[0] not in DERIVED_OUTPUTS:
        raise ConfigError(key, str(path), f"is inside the dataset {dataset}; choose a place outside it")


def _accepts_files(directory: Path, key: str, path: Path) -> None:
    """Refuse unless a file can be created in `directory` (probe: an unnamed temporary file, removed at once)."""
    try:
        with tempfile.TemporaryFile(dir=directory):
            pass
    except OSError as exc:
        raise ConfigError(key, str(path), f"cannot write in {directory} ({exc.strerror or exc})") from None


def _existing_parent(path: Path, key: str) -> Path:
    parent = path.parent
    if not parent.exists():
        raise ConfigError(key, str(path), f"directory {parent} does not exist")
    if not parent.is_dir():
        raise ConfigError(key, str(path), f"{parent} is not a directory")
    return parent


def output_file(path: str | os.PathLike, key: str, *, replace: bool = False, replace_option: str | None = None) -> Path:
    """A file about to be written: checked name, existing writable parent, not a directory, and not an existing
    file unless `replace` (the refusal names `replace_option`, the option that allows it, if there is one)."""
    path = checked_name(path, key)
    _outside_datasets(path, key)
    if path.exists() and not replace:
        hint = f"; use {replace_option} to replace it" if replace_option else ""
        raise ConfigError(key, str(path), f"exists; refusing to overwrite it{hint}")
    if path.is_dir():
        raise ConfigError(key, str(path), "is a directory")
    _accepts_files(_existing_parent(path, key), key, path)
    return path


def output_dir(path: str | os.PathLike, key: str, *, empty: bool = False) -> Path:
    """A directory to write into: an existing directory that accepts files (and is empty, with `empty`), or a
    new one whose parent exists and accepts it. Nothing is created here: the writer makes it (``mkdir()``)."""
    path = checked_name(path, key)
    _outside_datasets(path, key)
    if path.exists():
        if not path.is_dir():
            raise ConfigError(key, str(path), "exists and is not a directory")
        if empty and any(path.iterdir()):
            raise ConfigError(key, str(path), "exists and is not empty; choose a new directory")
        _accepts_files(path, key, path)
    else:
        _accepts_files(_existing_parent(path, key), key, path)
    return path
