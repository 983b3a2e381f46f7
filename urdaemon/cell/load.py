"""Read a cell file: YAML → validated, frozen ``Cell``, or a ``ConfigError`` naming file, key and reason."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from urdaemon.cell.config import Cell
from urdaemon.errors import ConfigError

__all__ = ["MAX_YAML_DEPTH", "format_location", "load_cell", "load_yaml", "parse_cell", "summarize"]

MAX_YAML_DEPTH = 64
"""Deepest nesting of lists and mappings a user's YAML file may have: a cell file needs 6, a
calibration file 4; PyYAML builds a deeper one by recursion and dies of a ``RecursionError``."""


def load_cell(path: str | Path) -> Cell:
    """Load and validate the cell file at ``path``."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise ConfigError(f"{path}: cannot read: {err.strerror or err}") from err
    except UnicodeDecodeError as err:
        raise ConfigError(f"{path}: not UTF-8 text (byte {err.start}): {err.reason}") from err
    return parse_cell(text, source=str(path), base_dir=path.resolve().parent)


def parse_cell(text: str, *, source: str = "<string>", base_dir: Path | None = None) -> Cell:
    """Validate cell-file text; relative paths inside resolve against ``base_dir``."""
    data = load_yaml(text, source)
    if not isinstance(data, dict):
        raise ConfigError(
            f"{source}: the cell file must be a mapping with 'cell' and 'robots', got {type(data).__name__}"
        )
    try:
        return Cell.model_validate(data, context={"base_dir": base_dir})
    except ValidationError as err:
        messages = [_message(source, e, data) for e in err.errors()]
        raise ConfigError("\n".join(messages), errors=messages) from err


def load_yaml(text: str, source: str) -> Any:
    """A user's YAML text (a cell or calibration file) as plain values; ``ConfigError`` naming ``source``,
    the line and the problem for text that is not YAML, a key given twice in one mapping, or nesting
    deeper than ``MAX_YAML_DEPTH``."""
    try:
        return yaml.load(text, Loader=_UniqueKeyLoader)  # a SafeLoader subclass: safe
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
        problem = getattr(err, "problem", None) or str(err)
        raise ConfigError(f"{source}{where}: not valid YAML: {problem}") from err


class _UniqueKeyLoader(yaml.SafeLoader):
    """A safe loader that refuses a key given twice in one mapping (plain YAML keeps the last) and
    nesting deeper than ``MAX_YAML_DEPTH`` (before the recursive composer could overflow the stack)."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent: yaml.Node | None, index: Any) -> yaml.Node | None:
        self._depth += 1
        try:
            if self._depth > MAX_YAML_DEPTH:
                raise yaml.composer.ComposerError(
                    None,
                    None,
                    f"nested deeper than {MAX_YAML_DEPTH} levels of lists and mappings",
                    self.peek_event().start_mark,  # type: ignore[no-untyped-call]
                )
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            try:
                hash(key)
            except TypeError:
                raise yaml.constructor.ConstructorError(
                    None,
                    None,
                    "a mapping key must be a plain value, not a list or mapping",
                    key_node.start_mark,
                ) from None
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r}", key_node.start_mark
                )
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


# YAML 1.2 (and JSON) read 1e-3 and 25e6 as numbers; PyYAML's YAML 1.1 wants a dot and a signed
# exponent (1.0e-3) and gives text otherwise, which the strict schema would refuse as "not a number".
_UniqueKeyLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


def _message(source: str, error: Any, data: Any) -> str:
    reason = _reason(error)
    if not error["loc"] and reason.startswith(("robots", "cell", "zenoh", "publish")):
        return f"{source}: {reason}"  # a whole-cell check that names its own key path
    return f"{source}: {format_location(error['loc'], data)}: {reason}"


def format_location(loc: tuple[int | str, ...], data: Any) -> str:
    """Render a pydantic error location as a key path, naming robots: ``robots[1] (bob).ports.reverse``."""
    parts: list[str] = []
    node: Any = data
    for item in loc:
        if isinstance(item, int):
            label = f"[{item}]"
            if isinstance(node, list) and 0 <= item < len(node):
                node = node[item]
                name = node.get("name") if isinstance(node, dict) else None
                if isinstance(name, str):
                    label += f" ({name})"
            else:
                node = None
            if parts:
                parts[-1] += label
            else:
                parts.append(label)
            continue
        # pydantic adds the union member or validator name as an extra path element; drop those
        if (
            not (isinstance(node, dict) and item in node)
            and parts
            and item.startswith(("function-", "tuple[", "dict[", "list[", "float", "int", "str"))
        ):
            continue
        parts.append(str(item))
        node = node.get(item) if isinstance(node, dict) else None
    return ".".join(parts) if parts else "(top level)"


_EXPECTED = {"float_type": "a number", "int_type": "an integer", "bool_type": "a boolean (true or false)"}
"""What a strict number or flag field wanted, by pydantic's error type."""


def _given(value: Any) -> str:
    """How a user wrote ``value`` in YAML, for a type error."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        try:
            float(value)
        except ValueError:
            return f"the text {value!r}"
        return f"the text {value!r} (write a number without quotes)"
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, list | tuple):
        return "a list"
    return "a mapping" if isinstance(value, dict) else "a value"


def _reason(error: Any) -> str:
    kind = error.get("type", "")
    msg = str(error.get("msg", "invalid"))
    if kind in _EXPECTED:
        return f"must be {_EXPECTED[kind]}, not {_given(error.get('input'))}"
    if kind == "extra_forbidden":
        return "unknown key (not part of the cell file format)"
    if kind == "missing":
        loc = error.get("loc", ())
        if loc and isinstance(loc[-1], int):
            return f"too few values: item {loc[-1]} is missing"
        return "required key is missing"
    return msg.removeprefix("Value error, ")


def summarize(cell: Cell) -> str:
    """A human summary of a valid cell."""
    lines = [
        f"cell {cell.cell!r}: {len(cell.robots)} robot(s); zenoh {cell.zenoh.mode} "
        f"listen={list(cell.zenoh.listen)} connect={list(cell.zenoh.connect)}"
    ]
    for r in cell.robots:
        where = f" at {r.address}" if r.address else ""
        if r.servo is not None:  # a servo arm listens on no port: what it drives is what matters
            links = f"outputs={', '.join(o.label for o in r.servo.outputs)}"
        else:
            links = f"ports={'/'.join(str(p) for p in r.ports.as_dict().values())}"
        pose = f"xyz={list(r.pose.xyz)} rpy={list(r.pose.rpy)} parent={r.pose.parent}"
        extra = f" calibration={r.calibration}" if r.calibration else ""
        lines.append(f"  {r.name}: {r.model} backend={r.backend}{where} {links} {pose}{extra}")
    return "\n".join(lines)
