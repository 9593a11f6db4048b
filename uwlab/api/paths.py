"""The bundled configs (designs, plans, rigs, sensors, fit configs): `config_path`; and how the API takes paths and
names its arguments: `config_file` (a file here, else a bundled config of that name) and `python_names` (an error
names the Python argument, ``out``, where the command line names its option, ``--out``)."""

from __future__ import annotations

import os
import re
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from uwlab.errors import ConfigError


def config_path(relative: str) -> Path:
    """The path of a bundled config file, relative to the configs directory (``UWLAB_CONFIG_DIR``, default the
    repository's ``configs/``); refused (one line) when it does not exist.

    Examples
    --------
    >>> import uwlab
    >>> uwlab.config_path("design/example.toml").name
    'example.toml'
    """
    from uwlab.model.data import config_dir

    path = config_dir() / relative
    if not path.exists():
        raise ConfigError("config", relative, f"no such file under {config_dir()}")
    return path


def config_file(path: str | os.PathLike[str], key: str) -> Path:
    """A config file an API function was given: the path itself when it exists or is absolute (the reader then
    refuses a missing one), else the bundled config of that name (`config_path`), so that
    ``uwlab.sweep("plans/tank-exposure-sweep.toml", ...)`` runs from any folder; a file of the working directory
    wins over a bundled one of the same name. Refused (one line naming `key`) when neither exists.

    >>> config_file("plans/tank-exposure-sweep.toml", "plan").parts[-2:]
    ('plans', 'tank-exposure-sweep.toml')
    >>> config_file("plans/no-such-plan.toml", "plan")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    uwlab.errors.ConfigError: plan = 'plans/no-such-plan.toml': no such file here or under .../configs
    """
    from uwlab.model.data import config_dir

    given = Path(path)
    if given.exists() or given.is_absolute():
        return given
    bundled = config_dir() / given
    if bundled.exists():
        return bundled
    raise ConfigError(key, os.fspath(path), f"no such file here or under {config_dir()}")


# Command-line options whose Python form is not the option's name: a boolean flag is written `flag=True`; `uwlab sweep
# --resume DIR` is `uwlab.sweep(..., out=DIR, resume=True)`.
_KEYS = {"--resume": "out"}
_IN_SENTENCES = {"--force": "force=True", "--resume": "resume=True"}
_OPTION = re.compile(r"--[a-z][a-z0-9]*(?:-[a-z0-9]+)*")
_IN_SENTENCE = re.compile(rf"(?<![\w-]){_OPTION.pattern}(?![\w-])")


def python_key(option: str) -> str:
    """The Python argument of a command-line option (``--pixel-format`` → ``pixel_format``); other keys as given.

    >>> python_key("--pixel-format"), python_key("--resume"), python_key("sweep.kind")
    ('pixel_format', 'out', 'sweep.kind')
    """
    if not _OPTION.fullmatch(option):
        return option
    return _KEYS.get(option, option[2:].replace("-", "_"))


@contextmanager
def python_names() -> Iterator[None]:
    """Within the block, a `ConfigError` that names a command-line option (the key ``--out``, a hint "use --force")
    names the Python argument instead (``out``, "use force=True"): the experiments' checks are the CLI's, and their
    messages speak the CLI's language.

    >>> with python_names():
    ...     raise ConfigError("--out", "out/tank", "directory out does not exist; use --force to replace it")
    Traceback (most recent call last):
    ...
    uwlab.errors.ConfigError: out = 'out/tank': directory out does not exist; use force=True to replace it
    """
    try:
        yield
    except ConfigError as exc:
        reason = _IN_SENTENCE.sub(lambda m: _IN_SENTENCES.get(m.group(0), python_key(m.group(0))), exc.reason)
        key = python_key(exc.key)
        if (key, reason) == (exc.key, exc.reason):
            raise
        raise ConfigError(key, exc.value, reason).with_traceback(exc.__traceback__) from None
