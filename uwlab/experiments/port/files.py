"""Where the port workflow writes: output folders that never overwrite a recording, with one-line errors."""
from __future__ import annotations

from pathlib import Path

from uwlab.errors import ConfigError


def output_dir(path: str | Path, option: str, must_be_new: bool = False) -> Path:
    """Create `path` (and parents) for writing; with must_be_new, refuse a folder that already holds files."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise ConfigError(option, str(out), "exists and is not a folder")
    if must_be_new and out.is_dir() and any(out.iterdir()):
        raise ConfigError(option, str(out), "is not empty; refusing to overwrite a recording")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(option, str(out), f"cannot create ({exc.strerror})") from None
    if not _writable(out):
        raise ConfigError(option, str(out), "is not writable")
    return out


def _writable(folder: Path) -> bool:
    probe = folder / ".uwlab-write-test"
    try:
        probe.touch()
        probe.unlink()
    except OSError:
        return False
    return True
