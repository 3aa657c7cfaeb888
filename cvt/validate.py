"""Checking values at the edge: one parser per kind of value, shared by the command line
and the Python API.

Each function takes the raw value (a string from the command line, or whatever a caller
passed) and the name the user knows it by (``--sites`` on the command line,
``n_elements`` in Python), and returns the parsed value or raises :class:`InputError`
with one line that names the option and the bad value.
"""

from __future__ import annotations

import math
import numbers

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


def real_number(value, name: str, minimum: float | None = None, maximum: float | None = None,
                above: float | None = None, below: float | None = None) -> float:
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


def _range_text(minimum, maximum) -> str:
    if minimum is not None and maximum is not None:
        return f" between {minimum:g} and {maximum:g}"
    if minimum is not None:
        return f" >= {minimum:g}"
    if maximum is not None:
        return f" <= {maximum:g}"
    return ""
