"""Argument types of the command line: numbers checked where argparse reads them, with messages that name the option.

``parser.add_argument("--seed", type=integer(minimum=0))`` makes ``--seed -5`` fail before any work with
``error: --seed must be >= 0; got -5`` (the parser of :mod:`evio_lib.cli` prints the option name in front of the
message). Every command's ``add_*_arguments`` uses these, so the rules read the same everywhere.

>>> integer(minimum=0)("7"), real(above=0.0)("0.5")
(7, 0.5)
>>> real(above=0.0)("-1")
Traceback (most recent call last):
...
argparse.ArgumentTypeError: must be > 0; got -1
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Callable, Mapping

__all__ = ["integer", "real", "add_force_argument", "output_folder", "as_option_error", "parse_set_options",
           "settings_from_dict"]


def _show(value: float) -> str:
    """Return ``value`` as the user would type it (2.0 -> '2')."""
    return str(int(value)) if float(value).is_integer() else repr(value)


def integer(minimum: int | None = None) -> Callable[[str], int]:
    """Return an argparse type: the text as an int, at least ``minimum`` when given."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            expected = f"an integer >= {minimum}" if minimum is not None else "an integer"
            raise argparse.ArgumentTypeError(f"must be {expected}; got {text!r}") from None
        if minimum is not None and value < minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum}; got {text}")
        return value

    parse.__name__ = "integer"
    return parse


def real(*, above: float | None = None, at_least: float | None = None, below: float | None = None) -> Callable[[str], float]:
    """Return an argparse type: the text as a finite float, > ``above``, >= ``at_least`` and < ``below`` when given."""
    bounds = [f"> {_show(above)}" if above is not None else "", f">= {_show(at_least)}" if at_least is not None else "",
              f"< {_show(below)}" if below is not None else ""]
    rule = " and ".join(b for b in bounds if b)

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a number{' ' + rule if rule else ''}; got {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"must be a finite number{' ' + rule if rule else ''}; got {text}")
        if (above is not None and not value > above) or (at_least is not None and not value >= at_least) \
                or (below is not None and not value < below):
            raise argparse.ArgumentTypeError(f"must be {rule}; got {text}")
        return value

    parse.__name__ = "number"
    return parse


def add_force_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--force``: replace an existing non-empty output folder (see :mod:`evio_lib.io.output_dir`)."""
    parser.add_argument("--force", action="store_true",
                        help="replace the output folder if it already holds files (without it the command refuses, "
                             "before doing any work)")


def output_folder() -> Callable[[str], Path]:
    """Return an argparse type for an output folder: the text as a ``Path``, refusing an empty text.

    ``type=Path`` would turn ``--out ''`` into ``Path('.')``, the working folder, so the check must see the raw text.

    >>> output_folder()("runs/a")
    PosixPath('runs/a')
    >>> output_folder()("")
    Traceback (most recent call last):
    ...
    argparse.ArgumentTypeError: must be a folder path such as runs/out; got ''
    """

    def parse(text: str) -> Path:
        if not text.strip():
            raise argparse.ArgumentTypeError(f"must be a folder path such as runs/out; got {text!r}")
        return Path(text)

    parse.__name__ = "folder"
    return parse


def as_option_error(error: ValueError, options: Mapping[str, str]) -> ValueError:
    """Return ``error`` with its leading config field name replaced by the option that sets it, else ``error``.

    A config class names its fields (``bias_init must be ...``); the user typed the option (``--bias-init``).
    ``options`` maps field names to options.

    >>> str(as_option_error(ValueError("bias_init must be six numbers"), {"bias_init": "--bias-init"}))
    '--bias-init must be six numbers'
    """
    message = str(error)
    for field, option in options.items():
        if message.startswith(field + " ") or message.startswith(field + ":"):
            return ValueError(option + message[len(field):])
    return error


def parse_set_options(items: list[str]) -> dict:
    """Return the ``--set KEY=JSON`` options as a dict, refusing an item without ``=`` or with a value that is not JSON.

    >>> parse_set_options(["lr=0.001", 'data={"windows": 4}'])
    {'lr': 0.001, 'data': {'windows': 4}}
    """
    import json

    values = {}
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep:
            raise ValueError(f"--set expects KEY=JSON; got {item!r}")
        try:
            values[key] = json.loads(raw)
        except json.JSONDecodeError as exc:
            raise ValueError(f"--set {key}: the value must be JSON ({exc.msg}); got {raw!r}") from None
    return values


def settings_from_dict(cls, values: Mapping, what: str):
    """Return the dataclass ``cls(**values)``, refusing keys it does not have with one message naming ``what``.

    >>> from dataclasses import dataclass
    >>> @dataclass
    ... class C:
    ...     a: int = 1
    >>> settings_from_dict(C, {"b": 2}, "example settings")
    Traceback (most recent call last):
    ...
    ValueError: unknown example settings ['b']; known: ['a']
    """
    from dataclasses import fields

    known = {f.name for f in fields(cls)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"unknown {what} {unknown}; known: {sorted(known)}")
    return cls(**values)
