"""The URScript builtins' signatures, loaded from the table of facts ``functions.yaml``.

``load_signatures(series, version)`` gives the builtins a controller of that series (``"e"``: e-Series,
PolyScope 5.x; ``"cb3"``: CB3, PolyScope 3.x) and software version accepts, each with its parameters in
order and their defaults as URScript values (numbers, booleans, strings, :class:`UrList`,
:class:`UrPose`). A parameter without a default has :data:`REQUIRED`. A default that the controller
computes when the function is called (the current joint positions, the active TCP, "same as ``a``") is a
:class:`Computed` marker: the builtin receives the marker itself and resolves it (compare with ``is``
against the module constants, e.g. ``if tcp is ACTIVE_TCP``).

The file format (see the head of ``functions.yaml``) is ours; the facts come from UR's URScript manuals.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from functools import cache
from importlib import resources
from types import MappingProxyType
from typing import Any, Final

import yaml

from urdaemon.fakeur.urscript.runtime import UrList, UrPose

__all__ = [
    "ACTIVE_TCP",
    "CURRENT_JOINT_POSITIONS",
    "CURRENT_JOINT_SPEEDS",
    "REQUIRED",
    "SERIES",
    "Computed",
    "Param",
    "Signature",
    "Version",
    "all_signatures",
    "load_signatures",
]

Version = tuple[int, int]
SERIES: Final = ("e", "cb3")
"""The controller series the table knows: e-Series (PolyScope 5.x) and CB3 (PolyScope 3.x)."""


class _Required:
    """The marker of a parameter that has no default (the call must give it)."""

    _instance: _Required | None = None

    def __new__(cls) -> _Required:
        if cls._instance is None:
            cls._instance = super().__new__(cls)
        return cls._instance

    def __repr__(self) -> str:
        return "REQUIRED"

    def __reduce__(self) -> str:
        return "REQUIRED"


REQUIRED: Final = _Required()


@dataclass(frozen=True, slots=True)
class Computed:
    """A default the controller works out at call time; the builtin receives this marker and resolves it.

    ``name`` is one of: ``current_joint_positions``, ``current_joint_speeds``, ``active_tcp``, or
    ``param:<name>`` (the value given for parameter ``<name>`` of the same call, e.g. ``speedl``'s
    ``aRot`` defaults to ``a``; use :meth:`Computed.param`).
    """

    name: str

    @property
    def param(self) -> str | None:
        """The parameter whose value this default copies, or None for a controller-state default."""
        return self.name[6:] if self.name.startswith("param:") else None

    def __repr__(self) -> str:
        return f"Computed({self.name!r})"


_COMPUTED: Final[dict[str, Computed]] = {}


def _computed(name: str) -> Computed:
    return _COMPUTED.setdefault(name, Computed(name))


CURRENT_JOINT_POSITIONS: Final = _computed("current_joint_positions")
CURRENT_JOINT_SPEEDS: Final = _computed("current_joint_speeds")
ACTIVE_TCP: Final = _computed("active_tcp")
_CONTROLLER_STATE: Final = frozenset(_COMPUTED)


@dataclass(frozen=True, slots=True)
class Param:
    """One parameter: its name (what keyword arguments use) and default (:data:`REQUIRED` for none)."""

    name: str
    default: object = REQUIRED

    @property
    def required(self) -> bool:
        return self.default is REQUIRED


@dataclass(frozen=True, slots=True)
class Signature:
    """A builtin as a controller of one series/version accepts it.

    ``physical``: the call consumes time on the arm (motion, ``sleep``, ``sync``, blocking socket reads...);
    a ``sec`` program may not call it. ``since`` maps each series where the function exists to the first
    software version that has it (a series missing from it: never there); ``until`` to the first version
    that no longer has it. ``names_only`` maps a series to the first version whose compiler knows the name
    although the series does not have the function (CB3 3.14+ compiles programs that mention e-Series
    functions, e.g. urcl's script with ``force_mode_set_gain_scaling`` behind a run-time check): for such a
    controller ``supported`` is False, so a program that mentions the function compiles and calling it is
    a runtime error. ``documented`` is False for builtins real controllers accept that the manual does not
    list (e.g. ``get_joint_positions``); ``deprecated``: the manual calls it deprecated (it still works).
    """

    name: str
    params: tuple[Param, ...]
    physical: bool
    since: Mapping[str, Version] = field(default_factory=dict, hash=False)
    until: Mapping[str, Version] = field(default_factory=dict, hash=False)
    documented: bool = True
    deprecated: bool = False
    names_only: Mapping[str, Version] = field(default_factory=dict, hash=False)
    supported: bool = True

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)

    def available(self, series: str, version: Version) -> bool:
        """Whether a controller of ``series`` at ``version`` has this function."""
        first = self.since.get(series)
        if first is None or version < first:
            return False
        last = self.until.get(series)
        return last is None or version < last

    def known(self, series: str, version: Version) -> bool:
        """Whether that controller's compiler accepts a program that calls it (it may lack the function)."""
        first = self.names_only.get(series)
        return self.available(series, version) or (first is not None and version >= first)


_TABLE: Final = "functions.yaml"
_VERSION_TEXT: Final = re.compile(r"^(\d+)\.(\d+)$")
_NAME: Final = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_NEWEST: Final = 1000
"""A major version newer than any: where ``all_signatures`` looks at a function that was never removed."""


_SafeLoader: type[yaml.SafeLoader] = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class _UniqueKeyLoader(_SafeLoader):  # type: ignore[valid-type,misc]
    """A safe YAML loader that refuses a key written twice in one mapping (PyYAML keeps the last)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        keys = [self.construct_object(key, deep=deep) for key, _ in node.value]
        for index, key in enumerate(keys):
            if key in keys[:index]:
                raise ValueError(f"{_TABLE}: {key!r} written twice (line {node.start_mark.line + 1})")
        mapping: dict[Any, Any] = super().construct_mapping(node, deep=deep)
        return mapping


def _parse_table(text: str) -> dict[str, Any]:
    table = yaml.load(text, Loader=_UniqueKeyLoader)
    if not isinstance(table, dict) or not isinstance(table.get("functions"), dict):
        raise ValueError(f"{_TABLE}: expected a mapping with a 'functions' mapping")
    return table


@cache
def _raw_table() -> dict[str, Any]:
    return _parse_table(resources.files(__package__).joinpath(_TABLE).read_text(encoding="utf-8"))


def _signatures(table: Mapping[str, Any], series: str, version: Version) -> dict[str, Signature]:
    found: dict[str, Signature] = {}
    for name, entry in table["functions"].items():
        signature = _signature(name, entry, table.get("defaults", {}), series, version)
        if signature is not None:
            found[name] = signature
    return found


def load_signatures(series: str, version: tuple[int, ...]) -> Mapping[str, Signature]:
    """Every builtin a ``series`` controller at software ``version`` accepts, by name.

    ``version`` is (major, minor), or longer (the rest is ignored: patch releases add no builtins). The
    mapping is read-only and shared (cached per series and version).
    """
    if series not in SERIES:
        raise ValueError(f"unknown controller series {series!r} (expected one of {', '.join(SERIES)})")
    return _load(series, (version[0], version[1]))


@cache
def _load(series: str, version: Version) -> Mapping[str, Signature]:
    return MappingProxyType(_signatures(_raw_table(), series, version))


@cache
def all_signatures() -> Mapping[str, Signature]:
    """Every builtin of the table in any series or version, by name, for checks across series.

    Each one's parameters are those of the newest version that has it (e-Series first, then CB3), so a
    compiler can tell "not available on this controller" from "no such function" (use
    :meth:`Signature.available` and :meth:`Signature.known`). Loading it checks every entry of the table
    at every version where it changes.
    """
    table = _raw_table()
    defaults = table.get("defaults", {})
    found: dict[str, Signature] = {}
    for name, entry in table["functions"].items():
        _check_entry(name, entry, defaults)
        for series in SERIES:
            until = _versions(name, entry, "until", {}).get(series)
            newest = (until[0], until[1] - 1) if until is not None else (_NEWEST, 0)
            signature = _signature(name, entry, defaults, series, newest)
            if signature is not None and signature.supported:
                found[name] = signature
                break
        else:
            raise ValueError(f"{_TABLE}: {name}: available in no series")
    return MappingProxyType(found)


def _check_entry(name: str, entry: Any, defaults: Mapping[str, Any]) -> None:
    """Parse ``entry`` at each version where it starts or changes: a malformed one raises ValueError."""
    if not isinstance(entry, dict):
        raise ValueError(f"{_TABLE}: {name!r}: expected an identifier mapped to a mapping")
    marks = [
        _versions(name, entry, key, defaults if key == "since" else {}) for key in ("since", "names_only")
    ]
    revisions = entry.get("revisions", [])
    if not isinstance(revisions, list):
        raise ValueError(f"{_TABLE}: {name}: revisions must be a list")
    marks += [_versions(name, revision, "since", {}) for revision in revisions]
    for versions in marks:
        for series, version in versions.items():
            _signature(name, entry, defaults, series, version)


def _signature(
    name: str, entry: Any, defaults: Mapping[str, Any], series: str, version: Version
) -> Signature | None:
    if not _NAME.match(name) or not isinstance(entry, dict):
        raise ValueError(f"{_TABLE}: {name!r}: expected an identifier mapped to a mapping")
    keys = {"params", "physical", "since", "until", "names_only", "revisions", "documented", "deprecated"}
    unknown = set(entry) - keys
    if unknown:
        raise ValueError(f"{_TABLE}: {name}: unknown keys {sorted(unknown)}")
    since = _versions(name, entry, "since", defaults)
    until = _versions(name, entry, "until", {})
    names_only = _versions(name, entry, "names_only", {})
    if set(names_only) & set(since):
        raise ValueError(f"{_TABLE}: {name}: names_only names a series that has the function")
    signature = Signature(
        name,
        (),
        False,
        MappingProxyType(since),
        MappingProxyType(until),
        names_only=MappingProxyType(names_only),
    )
    supported = signature.available(series, version)
    if not signature.known(series, version):
        return None
    params_entry = entry.get("params", [])
    for revision in entry.get("revisions", []):
        revision_since = _versions(name, revision, "since", {})
        if series in revision_since and version >= revision_since[series]:
            params_entry = revision["params"]
    params = tuple(_param(name, item, series) for item in params_entry)
    _check_params(name, params)
    physical = entry.get("physical", False)
    documented = entry.get("documented", True)
    deprecated = entry.get("deprecated", False)
    if not all(isinstance(flag, bool) for flag in (physical, documented, deprecated)):
        raise ValueError(f"{_TABLE}: {name}: physical, documented and deprecated must be booleans")
    return replace(
        signature,
        params=params,
        physical=physical,
        documented=documented,
        deprecated=deprecated,
        supported=supported,
    )


def _versions(
    name: str, entry: Mapping[str, Any], key: str, defaults: Mapping[str, Any]
) -> dict[str, Version]:
    raw = entry.get(key, defaults.get(key, {}))
    if not isinstance(raw, dict):
        raise ValueError(f"{_TABLE}: {name}: {key} must map series to versions")
    versions: dict[str, Version] = {}
    for series, text in raw.items():
        match = _VERSION_TEXT.match(str(text)) if isinstance(text, str) else None
        if series not in SERIES or match is None:
            raise ValueError(f'{_TABLE}: {name}: {key}: bad entry {series!r}: {text!r} (want e.g. e: "5.4")')
        versions[series] = (int(match[1]), int(match[2]))
    return versions


def _param(name: str, item: Any, series: str) -> Param:
    if isinstance(item, str):
        return Param(item)
    if isinstance(item, dict) and len(item) == 1:
        ((param_name, default),) = item.items()
        return Param(param_name, _value(f"{name}.{param_name}", default, series))
    raise ValueError(f"{_TABLE}: {name}: a parameter is a name or {{name: default}}, not {item!r}")


def _value(where: str, raw: Any, series: str) -> object:
    """A default written in the table, as the URScript value a builtin receives."""
    if isinstance(raw, bool | int | float | str):
        return raw
    if isinstance(raw, list):
        return UrList(_value(where, item, series) for item in raw)
    if isinstance(raw, dict) and len(raw) == 1:
        ((kind, payload),) = raw.items()
        if kind == "pose" and isinstance(payload, list) and len(payload) == 6:
            return UrPose(float(x) for x in payload)
        if kind == "computed" and isinstance(payload, str) and _computable(payload):
            return _computed(payload)
        if kind == "by_series" and isinstance(payload, dict) and series in payload:
            return _value(where, payload[series], series)
    raise ValueError(f"{_TABLE}: {where}: unsupported default {raw!r}")


def _computable(name: str) -> bool:
    return name in _CONTROLLER_STATE or (name.startswith("param:") and _NAME.match(name[6:]) is not None)


def _check_params(name: str, params: tuple[Param, ...]) -> None:
    names = [p.name for p in params]
    if len(set(names)) != len(names) or not all(_NAME.match(n) for n in names):
        raise ValueError(f"{_TABLE}: {name}: parameter names must be distinct identifiers: {names}")
    seen_default = False
    for param in params:
        if param.required and seen_default:
            raise ValueError(f"{_TABLE}: {name}: required parameter {param.name} after one with a default")
        seen_default = seen_default or not param.required
        ref = param.default.param if isinstance(param.default, Computed) else None
        if ref is not None and ref not in names[: names.index(param.name)]:
            raise ValueError(f"{_TABLE}: {name}.{param.name}: copies unknown or later parameter {ref}")
