"""Reading input files with one-line errors (docs/README.md "Bad input").

The loaders of missions, maps, DEMs and plans all read a text file and, for
YAML, parse it; a failure becomes the loader's ``InputError`` subclass naming
the file (and the line, for YAML syntax errors).
"""

from __future__ import annotations

from pathlib import Path

import yaml


def read_text(path, error: type[Exception], what: str = "", *, encoding: str = "utf-8",
              unreadable: str = "cannot read") -> str:
    """The text of ``path``, or ``error(path, problem)``.

    Parameters
    ----------
    what : str
        What the file is, added to "no such file" (e.g. "plan.json").
    encoding : str
        Strict decoding; a decoding error is an unreadable file.
    unreadable : str
        Start of the message when the file exists but cannot be read.
    """
    src = str(path)
    try:
        return Path(path).read_text(encoding=encoding, errors="strict")
    except FileNotFoundError:
        raise error(src, f"no such file ({what})" if what else "no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise error(src, f"{unreadable}: {exc}") from None


def parse_yaml(text: str, source: str, error: type[Exception]):
    """``yaml.safe_load(text)``, or ``error("<source>: line N", problem)``."""
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{source}: line {mark.line + 1}" if mark is not None else source
        raise error(where, f"not valid YAML: {getattr(exc, 'problem', None) or 'parse error'}") from None
