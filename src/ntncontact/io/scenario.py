"""Scenario files (TOML) and ``--set`` overrides -> the validated, typed configuration of
engine.config."""

from __future__ import annotations

import copy
import json
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ValidationError

from ..engine.config import MESH_TYPES, ScenarioConfig, ScenarioError

__all__ = ["Overrides", "Scenario", "apply_override", "load_config", "override_strings",
           "parse_scenario", "read_text", "read_toml", "toml_value", "tomllib"]

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


def _format_item(e: Any) -> str:
    parts = e["loc"]
    # drop the names pydantic adds to the path: validator functions and the mesh type tag
    loc = ".".join(str(p) for i, p in enumerate(parts) if not str(p).startswith("function-")
                   and not (i > 0 and parts[i - 1] == "mesh" and p in MESH_TYPES))
    msg = e["msg"].removeprefix("Value error, ")
    if e["type"] == "extra_forbidden":
        return f"{loc}: unknown key"
    if msg.startswith(f"{loc}.") or msg.startswith(f"{loc} "):
        return msg  # a check across keys that names them itself
    if isinstance(e["input"], dict):  # a check of a whole table: its message says what
        return f"{loc or '(top level)'}: {msg}"
    return f"{loc} = {_shown(e['input'])}: {msg}"


def toml_value(value: Any) -> str:
    """A Python value (NumPy's too) as a TOML value (the form ``--set key=value`` takes)."""
    if isinstance(value, np.generic | np.ndarray):
        value = value.tolist()
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):  # repr gives TOML's inf, -inf and nan
        return str(int(value)) if isinstance(value, int) else repr(float(value))
    if isinstance(value, str):  # a TOML basic string uses JSON's escapes; DEL is escaped too
        return json.dumps(value, ensure_ascii=False).replace("\x7f", "\\u007f")
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + "}"
    if isinstance(value, Sequence):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    raise TypeError(f"cannot give {value!r} ({type(value).__name__}) as a scenario value")


def _shown(value: Any, limit: int = 60) -> str:
    """A value as it would be written in the scenario file (shortened); one TOML cannot hold
    (None, an object in a dict) as Python shows it."""
    try:
        text = toml_value(value)
    except TypeError:
        text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def parse_scenario(data: dict[str, Any], path: Path) -> ScenarioConfig:
    """Validate a scenario mapping; the error is one line: the file, then each offending key
    with its value and what is wrong."""
    try:
        return ScenarioConfig.model_validate(data)
    except ValidationError as err:
        raise ScenarioError(f"{path}: " + "; ".join(_format_item(e) for e in err.errors())
                            ) from None


Overrides = Mapping[str, Any] | Sequence[str] | None


@dataclass(frozen=True)
class Scenario:
    """A validated scenario: its configuration, the folder its relative paths (meshes) are
    resolved against, where it came from, and the overrides applied (``key=value`` TOML)."""

    config: ScenarioConfig
    base_dir: Path
    source: str
    overrides: tuple[str, ...] = ()
    data: Mapping[str, Any] = field(default_factory=dict, repr=False)

    @classmethod
    def from_file(cls, path: str | Path, overrides: Overrides = None) -> Scenario:
        """A TOML scenario file, its relative paths resolved against its folder."""
        path = Path(path)
        return cls.from_data(read_toml(path), path.parent, str(path), overrides)

    @classmethod
    def from_data(cls, data: Mapping[str, Any], base_dir: Path, source: str,
                  overrides: Overrides = None) -> Scenario:
        """The mapping of a scenario file with ``overrides`` applied, validated; errors name
        ``source``."""
        items = override_strings(overrides)
        working = copy.deepcopy(dict(data))
        for item in items:
            apply_override(working, item, Path(source))
        return cls(parse_scenario(working, Path(source)), base_dir, source, items,
                   copy.deepcopy(dict(data)))

    def with_overrides(self, overrides: Overrides) -> Scenario:
        """The same scenario with more overrides applied (dotted keys, as ``--set``)."""
        return Scenario.from_data(self.data, self.base_dir, self.source,
                                  self.overrides + override_strings(overrides))


def override_strings(overrides: Overrides) -> tuple[str, ...]:
    """``{"analysis.dt": 0.01}`` -> ``("analysis.dt=0.01",)``; strings pass unchanged."""
    if overrides is None:
        return ()
    if isinstance(overrides, Mapping):
        return tuple(f"{key}={toml_value(value)}" for key, value in overrides.items())
    if isinstance(overrides, str):
        raise TypeError("overrides: give a mapping or a list of 'key=value' strings")
    return tuple(str(item) for item in overrides)


def load_config(path: str | Path, overrides: Overrides = None) -> ScenarioConfig:
    """The validated configuration of a TOML scenario, ``--set key=value`` overrides applied
    first (``api.load_scenario`` gives the :class:`Scenario`, which also knows its folder)."""
    return Scenario.from_file(path, overrides).config


def read_toml(path: Path) -> dict[str, Any]:
    """The mapping of a TOML file; a missing or unreadable file raises a ScenarioError."""
    if path.is_dir():  # it exists: "not found" would send the user looking for a typo
        found = sorted(p.name for p in path.glob("*.toml"))
        more = ", ..." if len(found) > 3 else ""
        hint = f" (it holds {', '.join(found[:3])}{more})" if found else ""
        raise ScenarioError(f"{path}: is a folder; expected a TOML file{hint}")
    if not path.is_file():
        raise ScenarioError(f"{path}: scenario file not found")
    try:
        return tomllib.loads(read_text(path))
    except tomllib.TOMLDecodeError as err:
        raise ScenarioError(f"{path}: not valid TOML: {err}") from None


def read_text(path: Path) -> str:
    """The file's text: TOML is UTF-8 (a leading byte-order mark is allowed). Other encodings
    are refused with a message naming the file, not decoded to garbage."""
    raw = path.read_bytes()
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise ScenarioError(f"{path}: the file is UTF-16 text; TOML scenario files must be "
                            "UTF-8 (save it as UTF-8)")
    if b"\x00" in raw:  # UTF-16 without a byte-order mark, or not text at all
        raise ScenarioError(f"{path}: the file holds NUL bytes (UTF-16 or binary?); TOML "
                            "scenario files are UTF-8 text")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        line = raw[: err.start].count(b"\n") + 1
        raise ScenarioError(f"{path}: not UTF-8 text (byte 0x{raw[err.start]:02x} on line "
                            f"{line}); TOML scenario files must be UTF-8") from None


def apply_override(data: dict[str, Any], item: str, path: Path) -> None:
    """Set a dotted key (list items by index), e.g. ``contact.0.friction=0.2``; value is TOML."""
    if "=" not in item:
        raise ScenarioError(f"{path}: override '{item}' must look like key.path=value")
    key, raw = item.split("=", 1)
    if not key.strip() or "" in key.strip().split("."):  # "=1" would set the key ""
        what = "an empty key" if not key.strip() else f"an empty part in the key '{key}'"
        raise ScenarioError(f"{path}: override '{item}' has {what}; it must look like "
                            "key.path=value")
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw  # a bare word is taken as a string
    parts = key.strip().split(".")
    node: Any = data
    for i, part in enumerate(parts[:-1]):
        node = _child(node, part, ".".join(parts[: i + 1]), path)
    last = parts[-1]
    if isinstance(node, list):
        node[_index(node, last, key, path)] = value
    elif isinstance(node, dict):
        node[last] = value
    else:
        raise ScenarioError(f"{path}: override '{key}': '{parts[-2]}' is not a table")


def _child(node: Any, part: str, where: str, path: Path) -> Any:
    if isinstance(node, list):
        return node[_index(node, part, where, path)]
    if isinstance(node, dict):
        return node.setdefault(part, {})
    raise ScenarioError(f"{path}: override: '{where}' is not a table or list")


def _index(node: list, part: str, where: str, path: Path) -> int:
    if not part.isdigit() or int(part) >= len(node):
        raise ScenarioError(f"{path}: override '{where}': no item {part} (list of {len(node)})")
    return int(part)
