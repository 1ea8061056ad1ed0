"""``format_version`` of the JSON files the companion writes (docs/README.md "Versions").

plan.json and report.json carry ``"format_version": "MAJOR.MINOR"``. A
minor version only adds keys, so a reader of ``1.0`` reads every ``1.x``
file (it ignores keys it does not know); a major version changes or removes
keys, so a reader rejects a major it does not know. A file without the key
predates versioning and is read as ``1.0``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from mavcore.inputs import brief


_VERSION = re.compile(r"(0|[1-9][0-9]*)\.(0|[1-9][0-9]*)")

#: Read as the version of a file that has no ``format_version`` key.
UNVERSIONED = "1.0"


@dataclass(frozen=True)
class FormatVersion:
    """A parsed ``MAJOR.MINOR`` format version."""

    major: int
    minor: int

    def __str__(self) -> str:
        return f"{self.major}.{self.minor}"


def check_format_version(doc: dict, supported_major: int | tuple[int, ...], source: str,
                         error: type[Exception]) -> FormatVersion:
    """The ``format_version`` of a parsed JSON document, checked for reading.

    Parameters
    ----------
    doc : dict
        The parsed document.
    supported_major : int or tuple of int
        The major version(s) this reader understands, the current one first.
    source : str
        The file name, for the error message.
    error : InputError subclass
        Raised as ``error("<source>: key 'format_version'", problem)``.

    Returns
    -------
    FormatVersion
        ``UNVERSIONED`` when the key is absent.

    Raises
    ------
    error
        The value is not a ``"MAJOR.MINOR"`` string, or its major is not
        one of ``supported_major``.
    """
    majors = (supported_major,) if isinstance(supported_major, int) else tuple(supported_major)
    value = doc.get("format_version", UNVERSIONED)
    where = f"{source}: key 'format_version'"
    match = _VERSION.fullmatch(value) if isinstance(value, str) else None
    if match is None:
        raise error(where, f'expected a string "MAJOR.MINOR" such as "{majors[0]}.0", got {brief(value)}')
    version = FormatVersion(int(match.group(1)), int(match.group(2)))
    if version.major not in majors:
        reads = " and ".join(f"{m}.x" for m in majors)
        raise error(where, f"version {version} is not supported (this companion reads {reads})")
    return version
