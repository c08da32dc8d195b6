"""``scene.toml``: a scene written as a TOML scene file, every default spelled out."""

from __future__ import annotations

import math
import re


def _toml_key(key: str) -> str:
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else _toml_string(key)


def _toml_string(text: str) -> str:
    """A TOML basic string: quotes, backslashes and control characters escaped, every
    other character as itself (an escaped astral character would be a surrogate pair,
    which TOML refuses); a lone surrogate, which no TOML string can hold, becomes U+FFFD."""
    return '"' + "".join(_toml_character(c) for c in text) + '"'


def _toml_character(c: str) -> str:
    if c in '"\\':
        return "\\" + c
    code = ord(c)
    if code < 0x20 or code == 0x7F:
        return f"\\u{code:04x}"
    if 0xD800 <= code <= 0xDFFF:
        return "\ufffd"
    return c


def _toml_comment(text: str) -> str:
    """``text`` fit for a TOML comment: no control character but tab (they are
    written as ``\\uXXXX``), no lone surrogate."""
    return "".join(c if c == "\t" else (_toml_character(c) if c not in '"\\' else c) for c in text)


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()) + " }" if value else "{}"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


def scene_to_toml(scene, header: str = "") -> str:
    """A scene as a TOML scene file that loads back to an equal :class:`~femgrid_mpm.scene.Scene`.

    Every key is written, defaults included.  ``header`` becomes comment lines.
    """
    data = scene.model_dump(mode="json", exclude_none=True)
    lines = [f"# {_toml_comment(line)}".rstrip() for line in header.split("\n")]

    def is_table_array(value) -> bool:
        return isinstance(value, list) and bool(value) and all(isinstance(v, dict) for v in value)

    # plain keys first: in TOML, a key after a [table] header belongs to that table
    lines += [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in data.items() if not isinstance(v, dict) and not is_table_array(v)]
    for key, value in data.items():
        if isinstance(value, dict):
            lines += ["", f"[{_toml_key(key)}]"] + [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()]
        elif is_table_array(value):
            for item in value:
                lines += ["", f"[[{_toml_key(key)}]]"] + [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in item.items()]
    return "\n".join(lines) + "\n"
