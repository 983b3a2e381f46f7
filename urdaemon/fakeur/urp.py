"""PolyScope program files (``.urp``) -> the URScript a controller would run for them.

A ``.urp`` is gzip-compressed XML, or plain XML as UR's PolyScope 3 example programs are stored
(``rtde_control_loop.urp`` of UR's RTDE client): ``<URProgram>`` holds ``<children>`` with an optional
``<SpecialSequence type="BeforeStart">`` and one ``<MainProgram>``, whose ``<children>`` are program
nodes. PolyScope turns that tree into a ``def`` program when it plays it; :func:`translate` does the
same for the nodes it knows and refuses the whole file, naming the node, for any other: the fake never
plays a program with a node silently dropped. Pure: bytes in, a :class:`UrpProgram` or a
:class:`UrpRefused` out; the caller reads the file.

The node formats come from public PolyScope programs and generators (see docs/fake-robot.md, "Program
files"); expressions are stored one ``<ExpressionChar character="x"/>`` per character. The URScript
written here is our model of PolyScope's code generation, not a copy of it: statements in the same
order, a ``$ n "label"`` step line before each (which the interpreter ignores as PolyScope's
controller does), ``runOnlyOnce="false"`` looping the main body forever.

A ``<name>.script`` that PolyScope saved next to the ``.urp`` is not read: a controller regenerates the
script from the ``.urp`` when it plays it, so the ``.urp`` is what counts.
"""

from __future__ import annotations

import re
import zlib
from dataclasses import dataclass
from xml.etree import ElementTree

__all__ = ["MAX_URP_BYTES", "MAX_URP_ELEMENTS", "UrpProgram", "UrpRefused", "translate"]

MAX_URP_BYTES = 256 * 1024
"""The largest decompressed program the fake reads (UR's example programs hold 10-70 KB); also the
bound against a gzip bomb."""
MAX_URP_ELEMENTS = 8192
"""The most XML elements a program the fake reads may hold. UR's example programs hold 176-1330, at
50-150 bytes each, so a program written like them that fills :data:`MAX_URP_BYTES` holds about
5 000; a file with more elements is not such a program. Within both bounds a translation costs up
to ~12 ms (2 400 pin references, 256 KiB; UR's timing_debug.urp 1.3 ms), more than a controller
cycle: ``load`` translates in the compiler thread (``dashboard_answers.dashboard_answer``)."""

EXTERNAL_CONTROL_NODE = "com.fzi.externalcontrol.ExternalControlNode"
"""The ``strategyClass`` of the External Control URCap's program node."""

_INDENT = "  "
_PINS_IN = {
    "digital_in": "get_standard_digital_in",
    "tool_in": "get_tool_digital_in",
    "config_in": "get_configurable_digital_in",
}
_PINS_OUT = {
    "digital_out": "set_standard_digital_out",
    "tool_out": "set_tool_digital_out",
    "config_out": "set_configurable_digital_out",
}
_PINS_READ = {  # a pin named in an expression (``<ExpressionIO>``) -> the builtin that reads it
    **_PINS_IN,
    "digital_out": "get_standard_digital_out",
    "tool_out": "get_tool_digital_out",
    "config_out": "get_configurable_digital_out",
    "GP_int_out": "read_output_integer_register",
    "GP_float_out": "read_output_float_register",
    "GP_bool_out": "read_output_boolean_register",
    "GP_int_in": "read_input_integer_register",
    "GP_float_in": "read_input_float_register",
    "GP_bool_in": "read_input_boolean_register",
}
_PINS_WRITE = {  # a pin a ``<Set type="ExpressionOutput">`` sets -> the builtin that writes it
    **_PINS_OUT,
    "GP_int_out": "write_output_integer_register",
    "GP_float_out": "write_output_float_register",
    "GP_bool_out": "write_output_boolean_register",
}
_PIN = re.compile(r"^([A-Za-z_]+)\[(\d+)\]$")
_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")
_EDITOR_SYMBOLS = {"\u225f": "==", "\u2260": "!=", "\u2264": "<=", "\u2265": ">="}
"""The expression editor's symbols (≟ ≠ ≤ ≥) stored in a program, and the operators they stand for."""
_POPUPS = {  # type -> (title, warning, error)
    "Message": ("Message", "False", "False"),
    "Warning": ("Warning", "True", "False"),
    "Error": ("Error", "False", "True"),
}


class UrpRefused(Exception):
    """The file is not a program the fake can play; ``reason`` says why (naming the node)."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


@dataclass(frozen=True, slots=True)
class UrpProgram:
    """A translated program: its ``def`` name and script, or the External Control program."""

    name: str
    script: str | None
    """The URScript to run; None for the External Control program (``external_control``)."""
    external_control: bool = False
    """The program is the External Control URCap's node alone: play fetches the daemon's script."""
    loops: bool = False
    """``runOnlyOnce="false"``: the main body runs again and again until stopped."""


def translate(data: bytes, file_name: str) -> UrpProgram:
    """The program a ``.urp`` file holds (``file_name`` names the def if the XML does not)."""
    return _program(_parse(data), file_name)


def _program(root: ElementTree.Element, file_name: str) -> UrpProgram:
    if root.tag != "URProgram":
        raise UrpRefused(f"not a PolyScope program: the root element is <{root.tag}>")
    name = _identifier(root.get("name") or file_name.rsplit("/", 1)[-1].removesuffix(".urp"))
    before: ElementTree.Element | None = None
    main: ElementTree.Element | None = None
    threads: list[ElementTree.Element] = []
    for node in _children(root):
        if node.tag == "MainProgram":
            main = node
        elif node.tag == "SpecialSequence" and node.get("type") == "BeforeStart":
            before = node
        elif node.tag == "Thread":
            threads.append(node)
        elif node.tag not in ("InitVariablesNode", "SubProgram"):
            raise UrpRefused(f"program node <{node.tag}> is not simulated by the fake")
    if main is None:
        raise UrpRefused("no <MainProgram> in the program")
    body = _children(main)
    if not body:
        raise UrpRefused("the program is empty")
    loops = main.get("runOnlyOnce", "true").lower() == "false"
    if any(_is_external_control(node) for node in body):
        if len(body) != 1 or before is not None or threads:
            raise UrpRefused("the External Control node is simulated only as the program's one node")
        return UrpProgram(name, None, external_control=True, loops=loops)
    writer = _Writer(_Tree(root))
    writer.line(1, f"def {name}():")
    if before is not None:
        writer.step(2, "BeforeStart")
        writer.nodes(2, _children(before))
    for thread in threads:
        writer.thread(2, thread)
    if loops:  # PolyScope labels the program's start inside the loop, once per round
        writer.line(2, "while (True):")
        writer.step(3, "Robot Program")
        writer.nodes(3, body)
        writer.line(2, "end")
    else:
        writer.step(2, "Robot Program")
        writer.nodes(2, body)
    writer.line(1, "end")
    return UrpProgram(name, writer.text(), loops=loops)


_GZIP_MAGIC = b"\x1f\x8b"
_XML_START = re.compile(rb"^(\xef\xbb\xbf)?\s*<")
"""A plain XML program: ``<`` first, after an optional UTF-8 byte order mark and white space."""


def _parse(data: bytes) -> ElementTree.Element:
    if data.startswith(_GZIP_MAGIC):
        xml = _decompress(data)
    elif _XML_START.match(data[:64]):  # plain XML, as UR's PolyScope 3 example programs are stored
        if len(data) > MAX_URP_BYTES:
            raise UrpRefused(f"the program is larger than {MAX_URP_BYTES} bytes")
        xml = data
    else:
        raise UrpRefused("not a program file: neither gzip-compressed nor XML")
    try:
        root = ElementTree.fromstring(xml)
    except ElementTree.ParseError as err:
        raise UrpRefused(f"the program's XML is malformed: {err}") from None
    if any(count >= MAX_URP_ELEMENTS for count, _ in enumerate(root.iter())):
        raise UrpRefused(f"the program has more than {MAX_URP_ELEMENTS} XML elements")
    return root


def _decompress(data: bytes) -> bytes:
    try:
        decompressor = zlib.decompressobj(wbits=16 + zlib.MAX_WBITS)
        xml = decompressor.decompress(data, MAX_URP_BYTES + 1)
    except zlib.error as err:
        raise UrpRefused(f"not a gzip-compressed program file: {err}") from None
    if len(xml) > MAX_URP_BYTES:
        raise UrpRefused(f"the program is larger than {MAX_URP_BYTES} bytes")
    if not decompressor.eof:
        if len(data) > MAX_URP_BYTES:
            raise UrpRefused(f"the program is larger than {MAX_URP_BYTES} bytes")
        raise UrpRefused("the compressed program is truncated")
    return xml


def _children(node: ElementTree.Element) -> list[ElementTree.Element]:
    """The program nodes under ``node`` (those in its ``<children>``)."""
    holder = node.find("children")
    return [] if holder is None else list(holder)


def _is_external_control(node: ElementTree.Element) -> bool:
    return node.tag == "Contributed" and node.get("strategyClass") == EXTERNAL_CONTROL_NODE


def _identifier(name: str) -> str:
    """A def name from a program name: other characters become ``_``, a leading digit gets a ``p``."""
    cleaned = re.sub(r"[^A-Za-z0-9_]", "_", name) or "program"
    return f"p{cleaned}" if cleaned[0].isdigit() else cleaned


def _label(text: str) -> str:
    """Text for a step label: one line, no double quotes (the pendant's symbols stay, as PolyScope
    writes them)."""
    return text.replace('"', "'").replace("\n", " ").replace("\r", " ")


_REFERENCE_STEP = re.compile(r"([A-Za-z_][\w.-]*)(?:\[(\d+)\])?")
_MAX_HOPS = 32
"""References followed from one element (a reference may point at another reference)."""


class _Tree:
    """The program's elements by parent, for resolving ``reference`` paths in time linear in the
    program: each element's parent, and each parent's children by tag, indexed when first needed."""

    def __init__(self, root: ElementTree.Element) -> None:
        self._parents = {child: parent for parent in root.iter() for child in parent}
        self._by_tag: dict[ElementTree.Element, dict[str, list[ElementTree.Element]]] = {}
        self._resolved: dict[ElementTree.Element, ElementTree.Element] = {}
        self.lookups = 0
        """Path steps followed so far (the work references cost, for tests)."""
        self.indexed = 0
        """Children indexed so far: each element at most once per translation."""

    def resolve(self, node: ElementTree.Element) -> ElementTree.Element:
        """The element a ``reference="../../If/children/Assignment[2]/variable"`` attribute points
        to (PolyScope writes a variable once and refers to it by its path from then on). Each path is
        followed once per translation: a reference to a reference reuses what the second resolved to."""
        chain: list[ElementTree.Element] = []
        while (path := node.get("reference")) is not None and node not in self._resolved:
            if len(chain) == _MAX_HOPS:
                raise UrpRefused(f"<{node.tag}>: more than {_MAX_HOPS} references in a row")
            chain.append(node)
            target = self._follow(node, path)
            if target is None:
                raise UrpRefused(f"<{node.tag}> refers to {path!r}, which is not in the program")
            node = target
        node = self._resolved.get(node, node)
        self._resolved.update(dict.fromkeys(chain, node))
        return node

    def _follow(self, node: ElementTree.Element, path: str) -> ElementTree.Element | None:
        target: ElementTree.Element | None = node
        for part in path.split("/"):
            self.lookups += 1
            if target is None:
                return None
            if part == "..":
                target = self._parents.get(target)
                continue
            match = _REFERENCE_STEP.fullmatch(part)
            if match is None:
                return None
            matches = self._children(target).get(match.group(1), [])
            index = int(match.group(2) or 1) - 1
            target = matches[index] if index < len(matches) else None
        return target

    def _children(self, parent: ElementTree.Element) -> dict[str, list[ElementTree.Element]]:
        index = self._by_tag.get(parent)
        if index is None:
            index = self._by_tag[parent] = {}
            for child in parent:
                index.setdefault(child.tag, []).append(child)
            self.indexed += len(parent)
        return index


def _variable_name(tree: _Tree, node: ElementTree.Element | None, what: str) -> str:
    name = "" if node is None else tree.resolve(node).get("name", "")
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
        raise UrpRefused(f"<{what}> names no variable")
    return name


def _expression(tree: _Tree, node: ElementTree.Element, what: str) -> str:
    """The expression a node stores one ``<ExpressionChar>`` per character, with
    ``<ExpressionToken>`` words (`` True ``, `` not ``) and ``<ExpressionVariable>`` elements standing
    for program variables."""
    holder = node.find("expression")
    if holder is None:
        raise UrpRefused(f"<{what}> without an <expression>")
    parts = []
    for part in holder:
        if part.tag == "ExpressionChar":
            character = part.get("character", "")
            parts.append(_EDITOR_SYMBOLS.get(character, character))
        elif part.tag == "ExpressionToken":  # a word the expression editor inserted whole
            parts.append(part.get("token", ""))
        elif part.tag == "ExpressionVariable" and len(part) == 1:
            parts.append(_variable_name(tree, part[0], what))
        elif part.tag == "ExpressionIO":
            reader, index = _pin(tree, part, _PINS_READ, what)
            parts.append(f"{reader}({index})")
        else:
            raise UrpRefused(f"<{what}>: expression part <{part.tag}> is not simulated by the fake")
    text = "".join(parts)
    if not text.strip():
        raise UrpRefused(f"<{what}> with an empty expression")
    return text


def _number(text: str | None, what: str) -> str:
    if text is None or not _NUMBER.match(text.strip()):
        raise UrpRefused(f"{what}: not a number: {text!r}")
    return text.strip()


def _pin(tree: _Tree, node: ElementTree.Element, table: dict[str, str], what: str) -> tuple[str, str]:
    """The builtin and index of a node's ``<pin referencedName="digital_in[2]"/>``."""
    pin = node.find("pin")
    name = "" if pin is None else tree.resolve(pin).get("referencedName", "")
    match = _PIN.match(name)
    if match is None or match.group(1) not in table:
        raise UrpRefused(f"<{what}> on pin {name!r} is not simulated by the fake")
    return table[match.group(1)], match.group(2)


def _digital(node: ElementTree.Element, what: str) -> str:
    value = (node.findtext("digitalValue") or "").strip()
    if value not in ("0", "1"):
        raise UrpRefused(f"<{what}>: digital value {value!r} is not 0 or 1")
    return "True" if value == "1" else "False"


class _Writer:
    """URScript lines with their indentation and PolyScope's step numbers."""

    def __init__(self, tree: _Tree) -> None:
        self.tree = tree
        """The program's elements, by which references are resolved."""
        self._lines: list[str] = []
        self._steps = 0
        self._open_if = False
        """An ``If`` (or ``ElseIf``) was written and its ``end`` waits for the next sibling."""

    def text(self) -> str:
        return "\n".join(self._lines) + "\n"

    def line(self, depth: int, text: str) -> None:
        self._lines.append(_INDENT * (depth - 1) + text)

    def step(self, depth: int, label: str) -> None:
        self._steps += 1
        self.line(depth, f'$ {self._steps} "{_label(label)}"')

    def nodes(self, depth: int, nodes: list[ElementTree.Element]) -> None:
        for index, node in enumerate(nodes):
            if node.tag == "If":
                self.branch(depth, node, nodes[index + 1] if index + 1 < len(nodes) else None)
                continue
            handler = _NODES.get(node.tag)
            if handler is None:
                what = node.get("strategyProgramNodeType") if node.tag == "Contributed" else None
                named = f"<{node.tag}> ({what})" if what else f"<{node.tag}>"
                raise UrpRefused(f"program node {named} is not simulated by the fake")
            handler(self, depth, node)

    # ---- one method per node ------------------------------------------------------------------------

    def wait(self, depth: int, node: ElementTree.Element) -> None:
        kind = node.get("type", "Sleep")
        if kind == "Sleep":
            seconds = _number(node.findtext("waitTime"), "<Wait> time")
            self.step(depth, f"Wait: {seconds}")
            self.line(depth, f"sleep({seconds})")
            return
        if kind == "DigitalInput":
            getter, index = _pin(self.tree, node, _PINS_IN, "Wait")
            condition = f"{getter}({index}) == {_digital(node, 'Wait')}"
        elif kind == "Condition":
            condition = _expression(self.tree, node, "Wait")
        else:
            raise UrpRefused(f'program node <Wait type="{kind}"> is not simulated by the fake')
        self.step(depth, f"Wait {condition}")
        self.line(depth, f"while (not({condition})):")
        self.line(depth + 1, "sync()")
        self.line(depth, "end")

    def script(self, depth: int, node: ElementTree.Element) -> None:
        kind = node.get("type", "Line")
        if kind == "Line":
            self.step(depth, "Script")
            self.line(depth, _expression(self.tree, node, "Script"))
            return
        contents = node.findtext("cachedContents")
        if contents is None:
            raise UrpRefused(f'<Script type="{kind}"> without <cachedContents>')
        self.step(depth, f"Script: {node.findtext('file') or kind}")
        for text in contents.splitlines():
            self.line(depth, text)

    def assignment(self, depth: int, node: ElementTree.Element) -> None:
        source = node.get("valueSource", "Expression")
        name = _variable_name(self.tree, node.find("variable"), "Assignment")
        if source != "Expression":
            raise UrpRefused(f'<Assignment valueSource="{source}"> to {name} is not simulated by the fake')
        value = _expression(self.tree, node, "Assignment")
        self.step(depth, f"{name} = {value}")
        self.line(depth, f"global {name} = {value}")

    def set(self, depth: int, node: ElementTree.Element) -> None:
        kind = node.get("type", "")
        if kind == "NoAction" and node.find("pin") is None:
            self.step(depth, "Set")
            return
        if kind == "DigitalOutput":
            setter, index = _pin(self.tree, node, _PINS_OUT, "Set")
            value = _digital(node, "Set")
        elif kind == "ExpressionOutput":
            setter, index = _pin(self.tree, node, _PINS_WRITE, "Set")
            value = _expression(self.tree, node, "Set")
        else:
            raise UrpRefused(f'program node <Set type="{kind}"> is not simulated by the fake')
        self.step(depth, f"Set {setter}({index})={value}")
        self.line(depth, f"{setter}({index}, {value})")

    def popup(self, depth: int, node: ElementTree.Element) -> None:
        kind = node.get("type", "Message")
        if kind not in _POPUPS:
            raise UrpRefused(f'program node <Popup type="{kind}"> is not simulated by the fake')
        title, warning, error = _POPUPS[kind]
        message = node.get("message", "").replace('"', "'")
        self.step(depth, f"Popup: {message}")
        self.line(depth, f'popup("{message}", "{title}", {warning}, {error}, blocking=True)')
        if node.get("haltProgram", "false").lower() == "true":
            self.line(depth, "halt")

    def comment(self, depth: int, node: ElementTree.Element) -> None:
        self.step(depth, f"'{node.get('comment', '')}'")

    def folder(self, depth: int, node: ElementTree.Element) -> None:
        self.step(depth, node.get("name", "Folder"))
        self.nodes(depth, _children(node))

    def branch(self, depth: int, node: ElementTree.Element, after: ElementTree.Element | None) -> None:
        """One ``<If>`` of a chain: PolyScope saves ``If``, ``ElseIf`` and ``Else`` as siblings."""
        kind = node.get("type", "If")
        if node.get("checkContinuously", "false").lower() != "false":
            raise UrpRefused(f'<If type="{kind}" checkContinuously="true"> is not simulated by the fake')
        if kind == "If":
            opens = f"if ({_expression(self.tree, node, 'If')}):"
        elif kind == "ElseIf":
            opens = f"elif ({_expression(self.tree, node, 'If')}):"
        elif kind == "Else":
            opens = "else:"
        else:
            raise UrpRefused(f'program node <If type="{kind}"> is not simulated by the fake')
        if kind != "If" and not self._open_if:
            raise UrpRefused(f'<If type="{kind}"> follows no <If>')
        self.step(depth, kind)
        self.line(depth, opens)
        self.nodes(depth + 1, _children(node))
        continues = after is not None and after.tag == "If" and after.get("type") in ("ElseIf", "Else")
        self._open_if = continues and kind != "Else"
        if not continues or kind == "Else":
            self.line(depth, "end")

    def loop(self, depth: int, node: ElementTree.Element) -> None:
        kind = node.get("type", "")
        if kind == "Forever":
            self.step(depth, "Loop")
            self.line(depth, "while (True):")
            self.nodes(depth + 1, _children(node))
            self.line(depth, "end")
            return
        if kind != "While" or node.get("checkContinuously", "false").lower() != "false":
            raise UrpRefused(f'program node <Loop type="{kind}"> is not simulated by the fake')
        condition = _expression(self.tree, node, "Loop")
        self.step(depth, f"Loop {condition}")
        self.line(depth, f"while ({condition}):")
        self.nodes(depth + 1, _children(node))
        self.line(depth, "end")

    def thread(self, depth: int, node: ElementTree.Element) -> None:
        """A ``<Thread>``: defined, then started before the main program's body, looping unless
        ``runOnlyOnce``."""
        name = _identifier(node.get("name", "Thread"))
        self.step(depth, name)
        self.line(depth, f"thread {name}():")
        if node.get("runOnlyOnce", "false").lower() == "false":
            self.line(depth + 1, "while (True):")
            self.nodes(depth + 2, _children(node))
            self.line(depth + 1, "end")
        else:
            self.nodes(depth + 1, _children(node))
        self.line(depth, "end")
        self.line(depth, f"threadId_{name} = run {name}()")

    def suppressed(self, depth: int, node: ElementTree.Element) -> None:
        """A node the programmer suppressed: PolyScope keeps it in the tree and does not run it."""

    def halt(self, depth: int, node: ElementTree.Element) -> None:
        self.step(depth, "Halt")
        self.line(depth, "halt")

    def move(self, depth: int, node: ElementTree.Element) -> None:
        kind = node.get("motionType", "MoveJ")
        if kind not in ("MoveJ", "MoveL"):
            raise UrpRefused(f'program node <Move motionType="{kind}"> is not simulated by the fake')
        function = "movej" if kind == "MoveJ" else "movel"
        speed = _number(node.get("speed"), f"<Move> {kind} speed")
        acceleration = _number(node.get("acceleration"), f"<Move> {kind} acceleration")
        self.step(depth, kind)
        for point in _children(node):
            if point.tag != "Waypoint":  # a node between waypoints runs there
                self.nodes(depth + 1, [point])
                continue
            if point.get("type") == "Variable":  # a pose variable in the base frame
                _base_feature(node, kind)
                target = _variable_name(self.tree, point.find("variable"), "Waypoint")
                self.step(depth + 1, point.get("name", "Waypoint"))
                self.line(depth + 1, f"{function}({target}, a={acceleration}, v={speed})")
                continue
            q = _joint_angles(point)
            parameters = point.find("motionParameters")
            blend = None if parameters is None else parameters.get("blendRadius")
            radius = "" if blend is None else f", r={_number(blend, '<Waypoint> blend radius')}"
            self.step(depth + 1, point.get("name", "Waypoint"))
            self.line(depth + 1, f"{function}([{q}], a={acceleration}, v={speed}{radius})")


_BASE_FEATURES = ("Base", "Joint_0_name")
"""The names a ``<Move>``'s ``<feature>`` gives the robot's base frame (PolyScope 3 programs, and
generators writing for them, name it after joint 0)."""


def _base_feature(node: ElementTree.Element, kind: str) -> None:
    """Refuse variable waypoints of a move relative to any feature but the base: they are played as
    base-frame poses."""
    feature = node.find("feature")
    name = None if feature is None else feature.get("referencedName")
    if name is not None and name not in _BASE_FEATURES:
        raise UrpRefused(f"<Move> {kind} relative to feature {name!r} is not simulated by the fake")


def _joint_angles(point: ElementTree.Element) -> str:
    """A fixed waypoint's joint angles, as the list literal of a movej/movel."""
    name = point.get("name", "?")
    if point.get("type", "Fixed") != "Fixed":
        raise UrpRefused(f'<Waypoint type="{point.get("type")}"> {name} is not simulated by the fake')
    position = point.find("position")
    angles = None
    if position is not None:
        joints = position.find("JointAngles")
        angles = joints.get("angles") if joints is not None else position.get("joints")
    if angles is None:
        raise UrpRefused(f"<Waypoint> {name} carries no joint angles")
    values = [value.strip() for value in angles.split(",")]
    if len(values) != 6:
        raise UrpRefused(f"<Waypoint> {name}: {len(values)} joint angles, not 6")
    return ", ".join(_number(value, f"<Waypoint> {name} joint angle") for value in values)


_NODES = {
    "Wait": _Writer.wait,
    "Script": _Writer.script,
    "Assignment": _Writer.assignment,
    "Set": _Writer.set,
    "Popup": _Writer.popup,
    "Comment": _Writer.comment,
    "Folder": _Writer.folder,
    "Halt": _Writer.halt,
    "Move": _Writer.move,
    "Loop": _Writer.loop,
    "SuppressedNode": _Writer.suppressed,
}
