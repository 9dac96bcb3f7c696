"""ROS 1 classes of ROS 2-only types, built at run time from the ROS 2 installation micros_rt already uses.

A ROS 2 type with no ROS 1 package on this host (``test_msgs/msg/BasicTypes``) is defined in that installation's
``share/<pkg>/msg/<Name>.msg`` (``srv/*.srv``, ``action/*.action``, or the ``.idl`` where only that exists:
:func:`idl_to_ros2_text`; the Python of the ROS 2 helper,
``MICROS_RT_ROS2_PYTHON`` or ``.venv-ros2``, tells where it is, as do ``AMENT_PREFIX_PATH``'s prefixes). Each
definition is rewritten as the ROS 1 definition of ``pkg/Name`` (``pkg/NameRequest``/``Response``,
``pkg/NameAction`` and its parts as actionlib's genaction expands them) and genpy builds the classes from that
text, so their md5 is the one ROS 1 computes for it: stock ``rostopic echo`` and ``rosservice call`` accept them
once they can import the classes (:func:`write_python_modules` writes them as a package would install them).

The rewriting, field by field:

- primitives keep their names (ROS 2's ``byte`` and ``char`` are one byte on the wire, as ROS 1's);
- ``builtin_interfaces/Time`` and ``Duration`` are ROS 1's ``time`` and ``duration``; ``std_msgs/Header`` is ROS 1's
  ``Header`` (DESIGN.md's wire rule: no ``seq`` on DDS);
- a nested type is ROS 1's installed class when there is one (its field names must be the ROS 2 type's, compared
  lower-cased as the wire rule maps them, else the definition is refused naming the field), else it is rewritten
  from the ROS 2 installation in turn;
- bounded strings and sequences (``string<=10``, ``int32[<=5]``) are unbounded (the wire is the same; what ROS 2
  sends always fits);
- default values (ROS 2 only) are dropped; constants are kept (a string constant's quotes removed, a bool's
  ``true``/``false`` as ``True``/``False``);
- ``wstring`` has no ROS 1 type: refused, naming the field.

>>> ros1_field_line("int32[<=5] values [1, 2]", "pkg", lambda base, where: base, "Foo.msg")
'int32[] values'
"""

from __future__ import annotations

import os
import re
import threading
from pathlib import Path
from typing import Any, Callable, Dict, Iterable, List, Optional, Sequence, Tuple, Type

import genpy

from .exceptions import TypeMappingError
from .transports.dds.types import register_message_classes

__all__ = ["Ros2TypeError", "build_classes", "idl_to_ros2_text", "ros1_field_line", "ros2_action_class", "ros2_message_class",
           "ros2_service_class", "ros2_share_dirs", "python_modules_dir", "write_python_modules"]

SEPARATOR = "=" * 80 + "\n"
_PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32", "uint32",
               "int64", "uint64", "string"}
_FIELD = re.compile(r"^(?P<type>[A-Za-z][\w/]*)(?P<bound><=\d+)?(?P<array>\[(?:<=)?\d*\])?\s+(?P<name>\w+)"
                    r"(?P<rest>.*)$")
_HEADER = "std_msgs/Header"

_lock = threading.RLock()
_classes: Dict[Tuple[str, str], Any] = {}            # (ROS 2 type, share dirs) -> class
_texts: Dict[Tuple[str, str], str] = {}              # ("msg" | "srv", ROS 1 type built here) -> its ROS 1 text
_built: Dict[Tuple[str, str], Type[genpy.Message]] = {}   # (ROS 1 type, md5) -> class (build_classes)


class Ros2TypeError(TypeMappingError):
    """A ROS 2 type that has no ROS 1 form here; the message names the file and the field."""


# -- building classes from ROS 1 text ------------------------------------------------------------------------

def build_classes(type_name: str, definition: str, md5: str = "") -> Type[genpy.Message]:
    """The class of ``type_name`` built from its full ROS 1 definition (``message_definition``: its text, then
    each type it uses after a line of ``=``), checked against ``md5`` when given; built once per (type, md5),
    and every class built is known to the DDS mapping."""
    with _lock:
        found = _built.get((type_name, md5))
    if found is not None:
        return found
    import genpy.dynamic

    try:
        classes: Dict[str, Type[genpy.Message]] = genpy.dynamic.generate_dynamic(type_name, definition)
    except Exception as exc:  # genmsg's parse errors have no common base: say which type and why
        raise Ros2TypeError(f"cannot build {type_name} from its definition: {exc}") from None
    cls = classes.get(type_name)
    if cls is None:
        raise Ros2TypeError(f"the definition of {type_name} does not define it")
    if md5 and cls._md5sum != md5:
        raise Ros2TypeError(f"the definition of {type_name} gives md5 {cls._md5sum}, not the {md5} announced with "
                           "it")
    register_message_classes(classes)
    with _lock:
        return _built.setdefault((type_name, md5), cls)


def _sections(cls: Any) -> Dict[str, str]:
    """An installed class's full text as {type: its own text}, itself and every type it uses."""
    parts = str(cls._full_text).split(SEPARATOR)
    out = {cls._type: parts[0]}
    for part in parts[1:]:
        head, _, body = part.partition("\n")
        if head.startswith("MSG: "):
            out[head[5:].strip()] = body
    return out


def _full_text(own: str, deps: Dict[str, str]) -> str:
    return own + "".join(f"{SEPARATOR}MSG: {t}\n{text}" for t, text in deps.items())


# -- the ROS 2 installation --------------------------------------------------------------------------------

def ros2_share_dirs(python: Optional[str] = None) -> List[Path]:
    """The ``share`` directories of the ROS 2 installation: beside ``python`` (the ROS 2 helper's, by default
    ``MICROS_RT_ROS2_PYTHON`` or ``.venv-ros2``; not resolved, a venv's python is a link), then
    ``AMENT_PREFIX_PATH``'s prefixes."""
    if python is None:
        from .services.gateway import ros2_python

        python = ros2_python()
    prefixes = [Path(python).parent.parent] if python else []
    prefixes += [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    return [p / "share" for p in prefixes]


def _definition(shares: Sequence[Path], pkg: str, kind: str, name: str) -> Tuple[str, Path]:
    """The ROS 2 definition of ``pkg/kind/name`` in ROS 2's own syntax and its file: the ``.msg``/``.srv``/``.action``
    file, else the ``.idl`` one read back into that syntax (:func:`idl_to_ros2_text`)."""
    for share in shares:
        candidate = share / pkg / kind / f"{name}.{kind}"
        if candidate.is_file():
            return candidate.read_text(), candidate
    for share in shares:
        idl = share / pkg / kind / f"{name}.idl"
        if idl.is_file():
            return idl_to_ros2_text(idl.read_text(), kind, name, str(idl)), idl
    raise Ros2TypeError(f"{pkg}/{kind}/{name} is not installed in ROS 1 on this host, and its ROS 2 definition "
                        f"{pkg}/{kind}/{name}.{kind} (or .idl) is in none of "
                        f"{', '.join(str(s) for s in shares) or '(none)'}")


def _split_type(ros2_type: str, kind: str) -> Tuple[str, str]:
    """``pkg/kind/Name`` (or ``pkg/Name``) -> (pkg, Name); ValueError in words for anything else."""
    parts = ros2_type.split("/")
    if len(parts) == 3 and parts[1] == kind or len(parts) == 2:
        return parts[0], parts[-1]
    raise ValueError(f"{ros2_type!r} is not a ROS 2 {kind} type (expected 'pkg/{kind}/Name')")


def _installed(ros1_type: str) -> Optional[Any]:
    import roslib.message

    try:
        cls = roslib.message.get_message_class(ros1_type)
    except (ValueError, ImportError):
        return None
    return cls if isinstance(cls, type) and issubclass(cls, genpy.Message) else None


# -- IDL (rosidl's) -> ROS 2 text -------------------------------------------------------------------------------

_IDL_TYPES = {"boolean": "bool", "octet": "byte", "float": "float32", "double": "float64", "char": "char",
              "wchar": "wchar", "int8": "int8", "uint8": "uint8", "int16": "int16", "uint16": "uint16",
              "int32": "int32", "uint32": "uint32", "int64": "int64", "uint64": "uint64", "string": "string",
              "wstring": "wstring"}
_IDL_TOKEN = re.compile(r'"(?:\\.|[^"\\])*"|//[^\n]*|/\*.*?\*/|::|[A-Za-z_]\w*|-?\d[\w.+-]*|\S', re.S)


def _idl_tokens(text: str) -> List[str]:
    """rosidl's IDL as tokens, without comments, ``#include`` lines and annotations (``@verbatim(...)``,
    ``@default(...)``: ROS 1 has no default values, the comments do not count)."""
    text = "\n".join(line for line in text.splitlines() if not line.lstrip().startswith("#"))
    out: List[str] = []
    tokens = [t for t in _IDL_TOKEN.findall(text) if not t.startswith(("//", "/*"))]
    i = 0
    while i < len(tokens):
        if tokens[i] == "@":
            i += 2   # '@' and the annotation's name
            if i < len(tokens) and tokens[i] == "(":
                depth = 0
                while i < len(tokens):
                    depth += {"(": 1, ")": -1}.get(tokens[i], 0)
                    i += 1
                    if depth == 0:
                        break
            continue
        out.append(tokens[i])
        i += 1
    return out


def idl_to_ros2_text(text: str, kind: str, name: str, where: str) -> str:
    """A rosidl ``.idl`` file read back into ROS 2's ``.msg``/``.srv``/``.action`` syntax (what rosidl_adapter
    wrote it from): its structs (``Name``; ``Name_Request``/``_Response``; ``Name_Goal``/``_Result``/``_Feedback``),
    their constants (module ``<struct>_Constants``), typedef'd arrays, sequences and bounded strings. IDL's
    ``uint8`` is ROS's ``uint8`` (a ``char`` written as ``.msg`` became ``uint8`` too)."""
    tokens = _idl_tokens(text)
    aliases: Dict[str, Tuple[str, str]] = {}   # typedef name -> (ROS 2 base type, array suffix)
    structs: Dict[str, List[str]] = {}
    constants: Dict[str, List[str]] = {}
    pos = [0]

    def take(expected: Optional[str] = None) -> str:
        if pos[0] >= len(tokens):
            raise Ros2TypeError(f"{where}: the IDL ends early")
        token = tokens[pos[0]]
        if expected is not None and token != expected:
            raise Ros2TypeError(f"{where}: expected {expected!r} in the IDL, found {token!r}")
        pos[0] += 1
        return token

    def peek() -> str:
        return tokens[pos[0]] if pos[0] < len(tokens) else ""

    def read_type() -> Tuple[str, str]:
        """(ROS 2 base type, array suffix) of the type at the cursor."""
        first = take()
        if first == "sequence":
            take("<")
            base, suffix = read_type()
            if suffix:
                raise Ros2TypeError(f"{where}: a sequence of arrays has no ROS form")
            bound = ""
            if peek() == ",":
                take(",")
                bound = take()
            take(">")
            return base, f"[<={bound}]" if bound else "[]"
        if first in ("string", "wstring") and peek() == "<":
            take("<")
            bound = take()
            take(">")
            return f"{_IDL_TYPES[first]}<={bound}", ""
        if first == "unsigned" or first == "long" or first == "short":
            raise Ros2TypeError(f"{where}: the IDL type {first!r} is not one rosidl writes")
        parts = [first]
        while peek() == "::":
            take("::")
            parts.append(take())
        if len(parts) == 1:
            if first in aliases:
                return aliases[first]
            if first in _IDL_TYPES:
                return _IDL_TYPES[first], ""
            return first, ""   # a struct of this module
        if len(parts) == 3:
            return f"{parts[0]}/{parts[2]}", ""   # pkg::msg::Type
        raise Ros2TypeError(f"{where}: cannot read the IDL type {'::'.join(parts)!r}")

    def read_typed_name() -> Tuple[str, str, str]:
        """``T name;`` or ``T name[N];`` (a typedef's or a member's): (name, ROS 2 base type, array suffix)."""
        base, suffix = read_type()
        name_read = take()
        if peek() == "[":
            take("[")
            suffix = f"[{take()}]"
            take("]")
        take(";")
        return name_read, base, suffix

    def read_module() -> None:
        module = take()
        take("{")
        owner = module[: -len("_Constants")] if module.endswith("_Constants") else None
        while peek() != "}":
            read_declaration(owner)
        take("}")
        take(";")

    def read_declaration(constants_of: Optional[str]) -> None:
        token = peek()
        if token == "module":
            take()
            read_module()
        elif token == "typedef":
            take()
            alias, base, suffix = read_typed_name()
            aliases[alias] = (base, suffix)
        elif token == "const":
            take()
            base, _ = read_type()
            const_name = take()
            take("=")
            values = [take()]
            while peek() != ";":
                values.append(take())   # "a" "b": one string in parts
            take(";")
            if all(v.startswith('"') for v in values):
                value = '"' + "".join(v[1:-1] for v in values) + '"'
            else:
                value = {"TRUE": "true", "FALSE": "false"}.get("".join(values), "".join(values))
            constants.setdefault(constants_of or "", []).append(f"{base} {const_name}={value}")
        elif token == "struct":
            take()
            struct = take()
            take("{")
            members: List[str] = []
            while peek() != "}":
                member, base, suffix = read_typed_name()
                members.append(f"{base}{suffix} {member}")
            take("}")
            take(";")
            if members == ["uint8 structure_needs_at_least_one_member"]:
                members = []   # ROS 2's stand-in for an empty message
            structs[struct] = members
        else:
            raise Ros2TypeError(f"{where}: cannot read the IDL at {token!r}")

    while pos[0] < len(tokens):
        read_declaration(None)
    parts = {"msg": [name], "srv": [f"{name}_Request", f"{name}_Response"],
             "action": [f"{name}_Goal", f"{name}_Result", f"{name}_Feedback"]}[kind]
    missing = [p for p in parts if p not in structs]
    if missing:
        raise Ros2TypeError(f"{where}: the IDL defines no struct {', '.join(missing)}")
    return "---\n".join("".join(f"{line}\n" for line in (*constants.get(part, []), *structs[part]))
                        for part in parts)


# -- ROS 2 text -> ROS 1 text ------------------------------------------------------------------------------

def ros1_field_line(line: str, pkg: str, field_type: Callable[[str, str], str], where: str) -> str:
    """One line of a ROS 2 definition (no comment, not empty) as ROS 1's: ``field_type(base, where)`` gives the
    ROS 1 type of a field's base type (raising :class:`Ros2TypeError` when it has none)."""
    found = _FIELD.match(line)
    if found is None:
        raise Ros2TypeError(f"{where}: cannot read the line {line!r}")
    here = f"{where}: field {found['name']} ({found['type']}{found['bound'] or ''}{found['array'] or ''})"
    ftype = field_type(found["type"], here)
    array = found["array"] or ""
    if array.startswith("[<="):
        array = "[]"   # a bounded sequence: the same on the wire, and what ROS 2 sends fits
    rest = found["rest"].strip()
    if rest.startswith("="):   # a constant: kept (a string constant's value is the rest of the line)
        if ftype == "string":
            value = rest[1:].strip()
            if len(value) >= 2 and value[0] == value[-1] and value[0] in "'\"":
                value = value[1:-1]
        else:
            value = rest[1:].split("#")[0].strip()
            if ftype == "bool":   # ROS 2 writes true/false, genmsg reads Python's literals
                value = {"true": "True", "false": "False"}.get(value.lower(), value)
        return f"{ftype}{array} {found['name']}={value}"
    return f"{ftype}{array} {found['name']}"   # a default value (ROS 2 only) is dropped


_STRING_CONSTANT = re.compile(r"^string(<=\d+)?\s+\w+\s*=")


def _lines(text: str) -> List[str]:
    """A definition's lines without comments and blank lines (a string constant keeps its '#'s: ROS takes the
    rest of its line)."""
    out = []
    for raw in text.splitlines():
        line = raw.strip()
        if line and not _STRING_CONSTANT.match(line):
            line = line.split("#")[0].strip()
        if line:
            out.append(line)
    return out


def _field_names(text: str) -> List[str]:
    found = (_FIELD.match(line) for line in _lines(text))
    return [f["name"] for f in found if f is not None and not f["rest"].strip().startswith("=")]


class _Converter:
    """ROS 2 definitions rewritten as ROS 1's, nested ROS 2-only types included (see the module's text)."""

    def __init__(self, shares: Sequence[Path]) -> None:
        self.shares = shares
        self.deps: Dict[str, str] = {}       # every type the converted text uses -> its ROS 1 text
        self.rewritten: List[str] = []       # the ROS 2-only ones among them (ROS 1 names)
        self._active: List[str] = []

    def text(self, ros2_text: str, pkg: str, where: str) -> str:
        lines = [ros1_field_line(line, pkg, lambda base, here: self.field_type(base, pkg, here), where)
                 for line in _lines(ros2_text)]
        return "".join(f"{line}\n" for line in lines)

    def field_type(self, base: str, pkg: str, where: str) -> str:
        if base in _PRIMITIVES:
            return base
        if base == "wstring":
            raise Ros2TypeError(f"{where}: ROS 1 has no wstring (wide string); such a type cannot cross to ROS 1")
        full = base if "/" in base else f"{pkg}/{base}"
        if full == "builtin_interfaces/Time":
            return "time"
        if full == "builtin_interfaces/Duration":
            return "duration"
        if full in (_HEADER, "Header"):
            self._installed_deps(_HEADER, where)
            return "Header"
        if full in self.deps:
            return full
        dep_pkg, _, name = full.partition("/")
        installed = _installed(full)
        if installed is not None:
            self._check_layout(installed, dep_pkg, name, where)
            self._installed_deps(full, where)
            return full
        if full in self._active:
            raise Ros2TypeError(f"{where}: {full} contains itself ({' -> '.join(self._active)})")
        try:
            ros2_text, path = _definition(self.shares, dep_pkg, "msg", name)
        except Ros2TypeError as exc:
            raise Ros2TypeError(f"{where}: {exc}") from None
        self._active.append(full)
        try:
            text = self.text(ros2_text, dep_pkg, f"{path}")
        finally:
            self._active.pop()
        self.deps[full] = text
        self.rewritten.append(full)
        return full

    def _installed_deps(self, ros1_type: str, where: str) -> None:
        cls = _installed(ros1_type)
        if cls is None:
            raise Ros2TypeError(f"{where}: the ROS 1 message {ros1_type} is not installed on this host")
        for name, text in _sections(cls).items():
            self.deps.setdefault(name, text)

    def _check_layout(self, installed: Any, pkg: str, name: str, where: str) -> None:
        """The installed ROS 1 type must have the ROS 2 type's fields, in order (a type that changed between
        ROS 1 and ROS 2 would be misread on the wire)."""
        try:
            ros2_text, path = _definition(self.shares, pkg, "msg", name)
        except Ros2TypeError:
            return   # not in the ROS 2 installation: nothing to compare
        ros2_fields = _field_names(ros2_text)
        ros1_fields = list(installed.__slots__)
        # DESIGN.md's wire rule lower-cases names (sensor_msgs/CameraInfo's D K R P are ROS 2's d k r p)
        if [f.lower() for f in ros1_fields] != [f.lower() for f in ros2_fields]:
            raise Ros2TypeError(f"{where}: ROS 1's installed {installed._type} has the fields "
                                f"{', '.join(ros1_fields) or '(none)'}, ROS 2's {path} has "
                                f"{', '.join(ros2_fields) or '(none)'}: the two definitions differ")


def _remember(ros1_type: str, kind: str, text: str, converter: _Converter) -> None:
    with _lock:
        _texts[(kind, ros1_type)] = text
        for dep in converter.rewritten:
            _texts.setdefault(("msg", dep), converter.deps[dep])


def _cache_key(ros2_type: str, shares: Sequence[Path]) -> Tuple[str, str]:
    return ros2_type, os.pathsep.join(str(s) for s in shares)


# -- the three kinds ----------------------------------------------------------------------------------------

def ros2_message_class(ros2_type: str, *, python: Optional[str] = None) -> Type[genpy.Message]:
    """The ROS 1 class of ROS 2 message type ``ros2_type`` (``test_msgs/msg/BasicTypes``): the installed
    ``pkg.msg`` class when ROS 1 has the package, else built from the ROS 2 installation (see the module's text).
    Use it as any message class: ``nh.subscribe("/r2_custom", ros2_message_class("test_msgs/msg/BasicTypes"), cb)``.
    :class:`Ros2TypeError` names the file and field when it cannot be had."""
    pkg, name = _split_type(ros2_type, "msg")
    installed = _installed(f"{pkg}/{name}")
    if installed is not None:
        return installed   # type: ignore[no-any-return]
    shares = ros2_share_dirs(python)
    key = _cache_key(f"{pkg}/msg/{name}", shares)
    with _lock:
        found = _classes.get(key)
        if found is None:
            converter = _Converter(shares)
            ros2_text, path = _definition(shares, pkg, "msg", name)
            text = converter.text(ros2_text, pkg, str(path))
            found = _classes[key] = build_classes(f"{pkg}/{name}", _full_text(text, converter.deps))
            _remember(f"{pkg}/{name}", "msg", text, converter)
        return found


def _srv_md5(type_name: str, text: str, deps: Dict[str, str]) -> str:
    import genmsg  # type: ignore[import-untyped]
    import genmsg.msg_loader  # type: ignore[import-untyped]

    context = genmsg.MsgContext.create_default()
    for dep, dep_text in deps.items():
        context.register(dep, genmsg.msg_loader.load_msg_from_string(context, dep_text, dep))
    return str(genmsg.compute_md5(context, genmsg.msg_loader.load_srv_from_string(context, text, type_name)))


def ros2_service_class(ros2_type: str, *, python: Optional[str] = None) -> Any:
    """The ROS 1 service class of ROS 2 service type ``ros2_type`` (``test_msgs/srv/BasicTypes``): installed, else
    built from the ROS 2 installation; its ``_md5sum`` is ROS 1's for that definition, so ``rosservice call``
    and rospy clients with the same definition connect."""
    import roslib.message

    pkg, name = _split_type(ros2_type, "srv")
    try:
        installed = roslib.message.get_service_class(f"{pkg}/{name}")
    except (ValueError, ImportError):
        installed = None
    if installed is not None:
        return installed
    shares = ros2_share_dirs(python)
    key = _cache_key(f"{pkg}/srv/{name}", shares)
    with _lock:
        found = _classes.get(key)
        if found is not None:
            return found
        ros2_text, path = _definition(shares, pkg, "srv", name)
        parts = re.split(r"^---\s*$", ros2_text, flags=re.M)
        if len(parts) != 2:
            raise Ros2TypeError(f"{path}: expected a request and a response separated by '---'")
        converter = _Converter(shares)
        request, response = (converter.text(part, pkg, f"{path} ({which})")
                             for part, which in zip(parts, ("request", "response")))
        srv_text = f"{request}---\n{response}"
        md5 = _srv_md5(f"{pkg}/{name}", srv_text, converter.deps)
        classes = {suffix: build_classes(f"{pkg}/{name}{suffix}", _full_text(text, converter.deps))
                   for suffix, text in (("Request", request), ("Response", response))}
        found = _classes[key] = type(name, (), {"_type": f"{pkg}/{name}", "_md5sum": md5,
                                                "_request_class": classes["Request"],
                                                "_response_class": classes["Response"]})
        _remember(f"{pkg}/{name}", "srv", srv_text, converter)
        return found


def ros2_action_class(ros2_type: str, *, python: Optional[str] = None) -> Tuple[Any, str]:
    """The ROS 1 (actionlib) class ``pkg/NameAction`` of ROS 2 action type ``ros2_type``
    (``test_msgs/action/Fibonacci``) and where it came from (``installed`` or ``built from <file>``)."""
    pkg, name = _split_type(ros2_type, "action")
    installed = _installed(f"{pkg}/{name}Action")
    if installed is not None:
        return installed, "installed"
    shares = ros2_share_dirs(python)
    key = _cache_key(f"{pkg}/action/{name}", shares)
    ros2_text, path = _definition(shares, pkg, "action", name)
    with _lock:
        found = _classes.get(key)
        if found is None:
            found = _classes[key] = _action_from(ros2_text, path, pkg, name, shares)
        return found, f"built from {path}"


def _action_from(ros2_text: str, path: Path, pkg: str, name: str, shares: Sequence[Path]) -> Any:
    parts = re.split(r"^---\s*$", ros2_text, flags=re.M)
    if len(parts) != 3:
        raise Ros2TypeError(f"{path}: expected goal, result and feedback separated by '---'")
    converter = _Converter(shares)
    for dep in ("actionlib_msgs/GoalID", "actionlib_msgs/GoalStatus", _HEADER):
        converter._installed_deps(dep, str(path))
    texts = {part: converter.text(text, pkg, f"{path} ({part.lower()})")
             for part, text in zip(("Goal", "Result", "Feedback"), parts)}
    deps = dict(converter.deps)
    deps.update({
        f"{pkg}/{name}ActionGoal": f"Header header\nactionlib_msgs/GoalID goal_id\n{name}Goal goal\n",
        f"{pkg}/{name}ActionResult": f"Header header\nactionlib_msgs/GoalStatus status\n{name}Result result\n",
        f"{pkg}/{name}ActionFeedback": f"Header header\nactionlib_msgs/GoalStatus status\n{name}Feedback feedback\n",
        **{f"{pkg}/{name}{part}": text for part, text in texts.items()},
    })
    core = f"{name}ActionGoal action_goal\n{name}ActionResult action_result\n{name}ActionFeedback action_feedback\n"
    cls = build_classes(f"{pkg}/{name}Action", _full_text(core, deps))
    converter.rewritten += [t for t in deps if t.startswith(f"{pkg}/{name}")]
    converter.deps = deps
    _remember(f"{pkg}/{name}Action", "msg", core, converter)
    return cls


# -- for stock ROS 1 tools -----------------------------------------------------------------------------------

def python_modules_dir() -> Path:
    """Where :func:`write_python_modules` writes by default: ``$ROS_HOME/micros_rt/ros1_types`` (``~/.ros/...``)."""
    home = os.environ.get("ROS_HOME", "").strip() or os.path.join(os.path.expanduser("~"), ".ros")
    return Path(home) / "micros_rt" / "ros1_types"


def write_python_modules(directory: Optional[Path] = None, *, types: Optional[Iterable[str]] = None) -> List[str]:
    """Write the ROS 1 Python modules of the types built here (``types``: those ROS 1 names only) into
    ``directory`` as genpy writes a package's (``<dir>/<pkg>/msg/_Name.py``, ``srv/``), so stock tools import
    them with ``PYTHONPATH=<dir>``: ``rostopic echo``, ``rosservice call``. A package ROS 1 has installed is
    never written (it would hide the installed one). Returns the packages written."""
    import genmsg
    import genmsg.msg_loader
    from genpy.generator import msg_generator, srv_generator

    directory = directory or python_modules_dir()
    with _lock:
        texts = dict(_texts)
    wanted = set(types) if types is not None else None
    context = genmsg.MsgContext.create_default()
    for (kind, ros1_type), text in texts.items():
        if kind == "msg":
            context.register(ros1_type, genmsg.msg_loader.load_msg_from_string(context, text, ros1_type))
    _register_installed(context, texts)
    written: Dict[str, Dict[str, List[str]]] = {}
    for (kind, ros1_type), text in sorted(texts.items()):
        pkg, _, name = ros1_type.partition("/")
        if (wanted is not None and ros1_type not in wanted) or _package_installed(pkg, directory):
            continue
        out = directory / pkg / kind
        out.mkdir(parents=True, exist_ok=True)
        if kind == "msg":
            lines = msg_generator(context, context.get_registered(ros1_type), {})
        else:
            lines = srv_generator(context, genmsg.msg_loader.load_srv_from_string(context, text, ros1_type), {})
        source = "\n".join(lines) + "\n"
        tmp = out / f"._{name}.py.tmp{os.getpid()}"
        tmp.write_text(source)
        os.replace(tmp, out / f"_{name}.py")
        written.setdefault(pkg, {}).setdefault(kind, []).append(name)
    for pkg, kinds in written.items():
        (directory / pkg / "__init__.py").touch()
        for kind in kinds:
            names = sorted({p.stem[1:] for p in (directory / pkg / kind).glob("_*.py")})
            (directory / pkg / kind / "__init__.py").write_text("".join(f"from ._{n} import *\n" for n in names))
    return sorted(written)


def _register_installed(context: Any, texts: Dict[Tuple[str, str], str]) -> None:
    """Installed types the texts use, in the context too (their generated code imports them)."""
    import genmsg.msg_loader

    for text in texts.values():
        for raw in text.replace("---\n", "").splitlines():
            found = _FIELD.match(raw.strip())
            if found is None or found["type"] in _PRIMITIVES or found["type"] in ("time", "duration"):
                continue
            dep = _HEADER if found["type"] == "Header" else found["type"]
            if context.is_registered(dep):
                continue
            cls = _installed(dep)
            if cls is not None:
                for name, dep_text in _sections(cls).items():
                    if not context.is_registered(name):
                        context.register(name, genmsg.msg_loader.load_msg_from_string(context, dep_text, name))


def _package_installed(pkg: str, directory: Path) -> bool:
    """ROS 1 has ``pkg`` installed (not as modules written into ``directory``)."""
    import importlib.util

    try:
        spec = importlib.util.find_spec(pkg)
    except (ImportError, ValueError):
        return False
    where = [Path(p).resolve() for p in (spec.submodule_search_locations or [])] if spec is not None else []
    return spec is not None and not any(p.parent == directory.resolve() for p in where)
