"""Read a cell file: YAML → validated, frozen ``Cell``, or a ``ConfigError`` naming file, key path and reason."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from urdaemon.cell.config import Cell
from urdaemon.errors import ConfigError

__all__ = ["format_location", "load_cell", "parse_cell", "summarize"]


def load_cell(path: str | Path) -> Cell:
    """Load and validate the cell file at ``path``."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise ConfigError(f"{path}: cannot read: {err.strerror or err}") from err
    return parse_cell(text, source=str(path), base_dir=path.resolve().parent)


def parse_cell(text: str, *, source: str = "<string>", base_dir: Path | None = None) -> Cell:
    """Validate cell-file text; relative paths inside resolve against ``base_dir``."""
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
        problem = getattr(err, "problem", None) or str(err)
        raise ConfigError(f"{source}{where}: not valid YAML: {problem}") from err
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: the cell file must be a mapping with 'cell' and 'robots', got {type(data).__name__}")
    try:
        return Cell.model_validate(data, context={"base_dir": base_dir})
    except ValidationError as err:
        messages = [f"{source}: {format_location(e['loc'], data)}: {_reason(e)}" for e in err.errors()]
        raise ConfigError("\n".join(messages), errors=messages) from err


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
        if isinstance(node, dict) and item not in node and parts:
            if item.startswith(("function-", "tuple[", "dict[", "list[", "float", "int", "str")):
                continue
        parts.append(str(item))
        node = node.get(item) if isinstance(node, dict) else None
    return ".".join(parts) if parts else "(top level)"


def _reason(error: Any) -> str:
    kind = error.get("type", "")
    msg = str(error.get("msg", "invalid"))
    if kind == "extra_forbidden":
        return "unknown key (not part of the cell file format)"
    if kind == "missing":
        return "required key is missing"
    return msg.removeprefix("Value error, ")


def summarize(cell: Cell) -> str:
    """A human summary of a valid cell."""
    lines = [f"cell {cell.cell!r}: {len(cell.robots)} robot(s); zenoh {cell.zenoh.mode} "
             f"listen={list(cell.zenoh.listen)} connect={list(cell.zenoh.connect)}"]
    for r in cell.robots:
        ports = r.ports.as_dict()
        port_text = "/".join(str(p) for p in ports.values())
        where = f" at {r.address}" if r.address else ""
        pose = f"xyz={list(r.pose.xyz)} rpy={list(r.pose.rpy)} parent={r.pose.parent}"
        extra = f" calibration={r.calibration}" if r.calibration else ""
        lines.append(f"  {r.name}: {r.model} backend={r.backend}{where} ports={port_text} {pose}{extra}")
    return "\n".join(lines)
