"""Checking values at the edge: one parser per kind of value, shared by the command line
and the Python API.

Each function takes the raw value (a string from the command line, or whatever a caller
passed) and the name the user knows it by (``--elements`` on the command line,
``n_elements`` in Python), and returns the parsed value or raises :class:`InputError`
with one line that names the option and the bad value.
"""

from __future__ import annotations

import json
import math
import numbers
import os
import re

from .errors import InputError


def whole_number(value, name: str, minimum: int | None = 0, maximum: int | None = None) -> int:
    """An int in [minimum, maximum]: an int, an integral float or a string of digits."""
    bad = InputError(f"{name} must be a whole number{_range_text(minimum, maximum)}, got {value!r}")
    if isinstance(value, bool):
        raise bad
    if isinstance(value, numbers.Integral):
        k = int(value)
    elif isinstance(value, numbers.Real):
        if not math.isfinite(float(value)) or float(value) != int(value):
            raise bad
        k = int(value)
    elif isinstance(value, str):
        try:
            k = int(value.strip())
        except ValueError:
            raise bad from None
    else:
        raise bad
    if (minimum is not None and k < minimum) or (maximum is not None and k > maximum):
        raise bad
    return k


def real_number(
    value,
    name: str,
    minimum: float | None = None,
    maximum: float | None = None,
    above: float | None = None,
    below: float | None = None,
) -> float:
    """A finite float in [minimum, maximum] (and > ``above``, < ``below`` when given)."""
    limits = _range_text(minimum, maximum)
    if above is not None:
        limits += f" > {above:g}"
    if below is not None:
        limits += f"{' and' if limits else ''} < {below:g}"
    bad = InputError(f"{name} must be a finite number{limits}, got {value!r}")
    if isinstance(value, bool) or not isinstance(value, (numbers.Real, str)):
        raise bad
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise bad from None
    if not math.isfinite(x):
        raise bad
    if (minimum is not None and x < minimum) or (maximum is not None and x > maximum):
        raise bad
    if (above is not None and not x > above) or (below is not None and not x < below):
        raise bad
    return x


def one_of(value, name: str, choices) -> str:
    """``value`` if it is one of ``choices``."""
    choices = list(choices)
    if value not in choices:
        raise InputError(f"unknown {name} {value!r}; choose one of {', '.join(map(str, choices))}")
    return value


def name_list(text, name: str, choices=None) -> list[str] | None:
    """'a,b' -> ['a', 'b'] (None stays None), each checked against ``choices`` if given."""
    if text is None:
        return None
    items = [t.strip() for t in str(text).split(",") if t.strip()]
    if not items:
        raise InputError(f"{name}: empty list {text!r}")
    if choices is not None:
        for item in items:
            one_of(item, name, choices)
    return items


def live_backend(value, name: str = "backend"):
    """``value`` if it can compute a CVT iteration (``label`` and ``moments``), as a
    started backend from ``backends.create_backend`` can."""
    if not (callable(getattr(value, "moments", None)) and callable(getattr(value, "label", None))):
        raise InputError(f"{name} must be a live backend (backends.create_backend(name)), got {value!r}")
    return value


_UNITS = {"": 1, "k": 2**10, "m": 2**20, "g": 2**30, "t": 2**40}


def byte_size(value, name: str) -> int:
    """A memory size > 0 in bytes: a number of bytes, or a number with a unit K, M, G or
    T (powers of 1024; ``8G``, ``512MiB``, ``1.5 GB`` and ``2e9`` all work)."""
    bad = InputError(f"{name} must be a memory size such as 8G, 512M or 2e9 (bytes), got {value!r}")
    if isinstance(value, bool):
        raise bad
    if isinstance(value, numbers.Real):
        number, unit = float(value), ""
    else:
        match = re.fullmatch(r"\s*([0-9.eE+]+)\s*([kKmMgGtT]?)(?:i?[bB])?\s*", str(value))
        if not match:
            raise bad
        try:
            number, unit = float(match.group(1)), match.group(2).lower()
        except ValueError:
            raise bad from None
    size = number * _UNITS[unit]
    if not (math.isfinite(size) and 1 <= size < 2**63):
        raise bad
    return int(size)


JSON_MAX_BYTES = 64 * 2**20  # a settings or baseline file: far larger is no such file


def json_object(path, what: str, max_bytes: int = JSON_MAX_BYTES) -> dict:
    """The JSON object stored in the file ``path`` (``what`` names it in messages):
    a missing file, a folder, a file over ``max_bytes`` (sized before it is read:
    parsed json takes several times its size), invalid JSON and valid JSON that is not
    an object are each refused with one line."""
    path = os.fspath(path)
    if os.path.isdir(path):
        raise InputError(f"{what} {path} is a folder, not a json file")
    try:
        size = os.path.getsize(path)
    except OSError:
        size = 0  # missing or unreadable: said below
    if size > max_bytes:
        raise InputError(
            f"{what} {path} holds {size / 2**20:.0f} MiB, more than the {max_bytes / 2**20:.0f} MiB "
            "such a file can hold; it is not read"
        )
    try:
        with open(path, encoding="utf-8-sig") as fh:
            data = json.load(fh)
    except FileNotFoundError:
        raise InputError(f"{what} {path} does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read {what} {path}: {exc}") from None
    except ValueError as exc:
        raise InputError(f"{what} {path} is not valid json: {exc}") from None
    if not isinstance(data, dict):
        raise InputError(f"{what} {path} holds a json {type(data).__name__}, not an object")
    return data


def _number_text(x) -> str:
    return str(x) if isinstance(x, numbers.Integral) else f"{x:g}"


def _range_text(minimum, maximum) -> str:
    if minimum is not None and maximum is not None:
        return f" between {_number_text(minimum)} and {_number_text(maximum)}"
    if minimum is not None:
        return f" >= {_number_text(minimum)}"
    if maximum is not None:
        return f" <= {_number_text(maximum)}"
    return ""


__all__ = [
    "whole_number",
    "real_number",
    "one_of",
    "name_list",
    "live_backend",
    "byte_size",
    "JSON_MAX_BYTES",
    "json_object",
]
