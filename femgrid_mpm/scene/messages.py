"""One-line messages for a scene that does not validate: ``key: problem``.

pydantic reports every problem with its location in the model; a scene file's
reader wants the first one, named by its key in the file (``loads[0].at``),
in the file's words (``must be a number``, ``unknown key (did you mean
'spacing'?)``).
"""

from __future__ import annotations

import math
import re
from typing import Annotated, Union

import numpy as np

from ..effects import entries, kinds, tables


def describe_validation_error(error, model) -> str:
    """The first problem of a pydantic ``ValidationError`` as one line ``key: message``.

    Echoes of a problem are dropped (a list "too short" because its only
    item failed), and the branches of a union at one key (``dt``: a number
    or ``"auto"``) are merged into one message.  An unknown key is shown
    with the nearest known one of ``model``, the model validated (the
    :class:`~femgrid_mpm.scene.Scene`).
    """
    errors = error.errors(include_url=False)
    echoes = [
        e for e in errors
        if e["type"] == "too_short" and any(len(o["loc"]) > len(e["loc"]) and o["loc"][: len(e["loc"])] == e["loc"] for o in errors)
    ]
    problems = [(_location(e), e) for e in errors if e not in echoes] or [(_location(errors[0]), errors[0])]
    # an unknown key first: with a misspelt key, "unknown key (did you mean ...)"
    # says more than the "required key is missing" it also causes
    problems.sort(key=lambda problem: problem[1]["type"] not in _UNKNOWN_KEY)
    location, first = problems[0]
    messages: list[str] = []
    for where, e in problems:
        if where != location:
            continue
        message = _message(e, model)
        if messages and messages[0].startswith("must be ") and message.startswith("must be "):
            message = message.removeprefix("must be ")
        if message not in messages:
            messages.append(message)
    text = " or ".join(messages)
    if first["type"] not in ("missing", *_UNKNOWN_KEY, "value_error", "union_tag_invalid", "union_tag_not_found") and isinstance(
        first.get("input"), (str, int, float, bool)
    ):
        text += f" (got {_shown(first['input'])})"
    text = f"{location}: {text}" if location else text
    others = len({where for where, _ in problems} - {location})
    if others:
        text += f" (and {others} more problem(s))"
    return _one_line(text)


#: pydantic's error types for a key that is not a field (models; dataclasses)
_UNKNOWN_KEY = ("extra_forbidden", "unexpected_keyword_argument")
#: pydantic's name of a union branch or validator in a location: not a key
_BRANCH = re.compile(r"^(constrained-\w+|function-\w+\[.*|[\w-]+\[.*\]|int|float|str|bool|none)$")
#: the kinds of each scene table of several kinds: pydantic puts the kind after the table's item
_KIND_TAGS = {table: kinds(table) for table in tables() if len(entries(table)) > 1}


def _location(error: dict) -> str:
    location = error["loc"]
    if error["type"] in ("union_tag_invalid", "union_tag_not_found"):
        location = (*location, error.get("ctx", {}).get("discriminator", "'kind'").strip("'"))
    return _dotted(location, keep_last=error["type"] in _UNKNOWN_KEY)


def _is_kind_tag(location, position: int) -> bool:
    """Whether ``location[position]`` is the kind pydantic inserts after an item of
    a table of several kinds (``point`` in ``loads, 0, point, at``)."""
    head = location[:position]
    if len(head) == 2 and isinstance(head[1], int):
        table = head[0]  # an array of tables: loads[0]
    elif len(head) == 1:
        table = head[0]  # one table
    else:
        return False
    return location[position] in _KIND_TAGS.get(table, ())


def _dotted(location, keep_last: bool = False) -> str:
    parts = []
    for position, item in enumerate(location):
        last = position == len(location) - 1
        if isinstance(item, int):
            parts.append(f"[{item}]")
        elif not (keep_last and last) and (_is_kind_tag(location, position) or _BRANCH.match(str(item))):
            continue  # discriminator tags and validator/type names are not keys
        else:
            parts.append(("." if parts else "") + str(item))
    return "".join(parts)


def _message(error: dict, model) -> str:
    kind, context = error["type"], error.get("ctx", {})
    if kind in _UNKNOWN_KEY:
        return "unknown key" + _known_keys_hint(error["loc"], model)
    if kind == "union_tag_not_found" or (kind == "missing" and not isinstance(error["loc"][-1], int)):
        return "required key is missing"
    if kind == "finite_number":
        return "must be a finite number (not NaN or infinity)"
    if kind == "union_tag_invalid":
        return f"unknown kind {_shown(context.get('tag'))} (expected {context.get('expected_tags')})"
    if kind == "int_parsing_size":  # a number beyond what pydantic takes as a whole number (1e300)
        return f"must be a whole number of at most {2**63 - 1:.3g}"
    if kind in ("float_parsing", "int_parsing", "float_type", "int_type", "int_from_float"):
        return "must be a whole number" if kind.startswith("int") else "must be a number"
    if kind == "missing" and isinstance(error["loc"][-1], int):
        return "missing: the array is too short"
    if kind in ("too_long", "too_short") and "actual_length" in context:
        limit = context.get("max_length" if kind == "too_long" else "min_length")
        return f"must have {'at most' if kind == 'too_long' else 'at least'} {limit} item(s), not {context['actual_length']}"
    if kind in ("model_type", "dataclass_type", "dict_type", "model_attributes_type", "dataclass_exact_type"):
        return "must be a table"
    if kind in ("tuple_type", "list_type"):
        return "must be an array"
    bounds = {"greater_than": "gt", "greater_than_equal": "ge", "less_than": "lt", "less_than_equal": "le"}
    if kind in bounds and isinstance(context.get(bounds[kind]), float):  # 1e+30, not 30 digits
        words = {"gt": "greater than", "ge": "greater than or equal to", "lt": "less than",
                 "le": "less than or equal to"}[bounds[kind]]
        return f"must be {words} {context[bounds[kind]]:g}"
    message = error["msg"].removeprefix("Value error, ").removeprefix("Assertion failed, ")
    if message.startswith("Input should be "):
        message = "must be " + message.removeprefix("Input should be ")
    return message


def _known_keys_hint(location, model) -> str:
    """`` (did you mean 'spacing'?)`` or `` (known keys: ...)`` for an unknown key of ``model``; "" if unresolvable."""
    import difflib
    import typing

    node: object = model
    for item in location[:-1]:
        while typing.get_origin(node) is Annotated:
            node = typing.get_args(node)[0]
        if typing.get_origin(node) is Union:
            members = [m for m in typing.get_args(node) if m is not type(None)]
            # a discriminated union's location names the tag: the member whose ``kind`` it is
            tagged = [m for m in members if item in typing.get_args(_fields(m).get("kind", None) or ())]
            node = tagged[0] if tagged else members[0] if len(members) == 1 else None
            if tagged:
                continue
            while typing.get_origin(node) is Annotated:
                node = typing.get_args(node)[0]
        if isinstance(item, int) and typing.get_origin(node) is tuple:
            arguments = typing.get_args(node)
            node = arguments[0] if len(arguments) == 2 and arguments[1] is Ellipsis else None
        elif isinstance(item, str) and item in _fields(node):
            node = _fields(node)[item]
        else:
            return ""
    while typing.get_origin(node) in (Annotated, Union):
        members = [m for m in typing.get_args(node) if m is not type(None)]
        node = members[0] if typing.get_origin(node) is Annotated or len(members) == 1 else None
    known = list(_fields(node))
    if not known:
        return ""
    close = difflib.get_close_matches(str(location[-1]), known, n=1)
    return f" (did you mean {close[0]!r}?)" if close else f" (known keys: {', '.join(known)})"


def _fields(node) -> dict:
    """Field name -> annotation of a pydantic model or dataclass; {} for anything else."""
    fields = getattr(node, "model_fields", None) or getattr(node, "__pydantic_fields__", None)
    if not isinstance(fields, dict):
        return {}
    return {name: info.annotation for name, info in fields.items()}


#: the characters of a string, and the items of an array, a message shows (then "...")
SHOWN_CHARACTERS, SHOWN_ITEMS = 80, 16


def _shown(value, depth: int = 0) -> str:
    """A value as it would be written in TOML (``true``, ``"q3"``, ``nan``); numpy arrays as
    arrays, nesting beyond 8 levels as ``...``; a string beyond :data:`SHOWN_CHARACTERS`
    and an array beyond :data:`SHOWN_ITEMS` cut short, saying how long they are."""
    if depth > 8:
        return "..."
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        import json

        if len(value) > SHOWN_CHARACTERS:  # a message stays one readable line
            return json.dumps(value[:SHOWN_CHARACTERS])[:-1] + f'..." ({len(value)} characters)'
        return json.dumps(value)
    if isinstance(value, float) and not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, (np.ndarray, np.generic)):  # numpy arrays and scalars as Python values
        return _shown(value.tolist(), depth)
    if isinstance(value, (list, tuple)):
        shown = [_shown(item, depth + 1) for item in value[:SHOWN_ITEMS]]
        if len(value) > SHOWN_ITEMS:
            shown.append(f"... ({len(value)} items)")
        return "[" + ", ".join(shown) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{key} = {_shown(item, depth + 1)}" for key, item in value.items()) + "}"
    return repr(value)


def _one_line(text: str) -> str:
    return " ".join(text.split("\n"))
