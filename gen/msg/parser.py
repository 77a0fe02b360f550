"""Parser of ROS 2 ``.msg``, ``.srv`` and ``.action`` files (rosbags has none for the last two).

Services expand to ``pkg/srv/Name_Request`` and ``_Response``; actions to ``Name_Goal``,
``_Result``, ``_Feedback`` and the wire types ROS 2 generates from them: ``_SendGoal_Request``
``{goal_id, goal}``, ``_SendGoal_Response`` ``{accepted, stamp}``, ``_GetResult_Request``
``{goal_id}``, ``_GetResult_Response`` ``{status, result}``, ``_FeedbackMessage``
``{goal_id, feedback}``. Errors name the file, the line and the offending token.
"""

import re
from pathlib import Path

from .model import (
    PRIMITIVES,
    Array,
    Constant,
    Field,
    MessageDef,
    MessageDefinitionError,
    Named,
    Primitive,
    Sequence,
)

__all__ = ["parse_msg", "parse_srv", "parse_action", "parse_file", "parse_type"]

_TYPE = re.compile(r"^(?P<base>[A-Za-z][A-Za-z0-9_]*(?:/[A-Za-z][A-Za-z0-9_]*){0,2})"
                   r"(?:<=(?P<sbound>\d+))?(?P<array>\[(?P<abound><=)?(?P<n>\d*)\])?$")
_FIELD_NAME = re.compile(r"^[a-z][a-z0-9_]*$")
_CONST_NAME = re.compile(r"^[A-Z][A-Z0-9_]*$")
_SEPARATOR = re.compile(r"^---\s*$")


def parse_type(text, package, source="<string>", line=0):
    """Parse a type token (``uint8[]``, ``string<=8``, ``geometry_msgs/Point[3]``)."""
    mo = _TYPE.match(text)
    if mo is None:
        raise MessageDefinitionError(source, line, text, "malformed type")
    base = mo.group("base")
    if mo.group("sbound") is not None:
        if base not in ("string", "wstring"):
            raise MessageDefinitionError(source, line, text, "only strings take a <= bound")
        if int(mo.group("sbound")) == 0:
            raise MessageDefinitionError(source, line, text, "string bound must be >= 1")
        element = Primitive(base, int(mo.group("sbound")))
    elif base in PRIMITIVES:
        element = Primitive(base)
    elif base == "Header":
        element = Named("std_msgs/msg/Header")
    elif base in ("time", "duration"):
        element = Named(f"builtin_interfaces/msg/{base.capitalize()}")
    else:
        parts = base.split("/")
        if len(parts) == 1:
            element = Named(f"{package}/msg/{parts[0]}")
        elif len(parts) == 2:
            element = Named(f"{parts[0]}/msg/{parts[1]}")
        elif parts[1] == "msg":
            element = Named(base)
        else:
            raise MessageDefinitionError(source, line, text,
                                         "a field type must be a message (pkg/msg/Type)")
    if mo.group("array") is None:
        return element
    count = mo.group("n")
    if mo.group("abound"):
        if not count or int(count) == 0:
            raise MessageDefinitionError(source, line, text, "bad array bound: need <=N, N >= 1")
        return Sequence(element, int(count))
    if count == "":
        return Sequence(element)
    if int(count) == 0:
        raise MessageDefinitionError(source, line, text, "bad array bound: fixed arrays need N >= 1")
    return Array(element, int(count))


def _strip_comment(line):
    # A '#' inside a quoted string constant is not a comment.
    quote = None
    for i, ch in enumerate(line):
        if ch in "\"'" and quote is None:
            quote = ch
        elif ch == quote:
            quote = None
        elif ch == "#" and quote is None:
            return line[:i]
    return line


def _literal(type_, text, source, line):
    text = text.strip()
    try:
        if isinstance(type_, Primitive):
            if type_.is_string:
                if len(text) >= 2 and text[0] == text[-1] and text[0] in "\"'":
                    return text[1:-1]
                return text
            if type_.name == "bool":
                if text.lower() in ("true", "1"):
                    return True
                if text.lower() in ("false", "0"):
                    return False
                raise ValueError(text)
            if type_.name.startswith("float"):
                return float(text)
            return int(text, 0)
        if isinstance(type_, (Array, Sequence)):
            if not (text.startswith("[") and text.endswith("]")):
                raise ValueError(text)
            body = text[1:-1].strip()
            items = [s for s in body.split(",")] if body else []
            return [_literal(type_.element, s, source, line) for s in items]
    except ValueError:
        raise MessageDefinitionError(source, line, text, f"bad value for {type_}") from None
    raise MessageDefinitionError(source, line, text, "only primitives and arrays of them "
                                 "take default values")


def parse_msg(text, name, source="<string>", first_line=1):
    """Parse the text of one ``.msg`` (or one part of a ``.srv``/``.action``) as type ``name``."""
    package = name.split("/")[0]
    fields, constants, names = [], [], set()
    for number, raw in enumerate(text.splitlines(), start=first_line):
        line = _strip_comment(raw).strip()
        if not line:
            continue
        parts = line.split(None, 1)
        if len(parts) < 2:
            raise MessageDefinitionError(source, number, line, "expected 'TYPE NAME'")
        type_text, rest = parts
        type_ = parse_type(type_text, package, source, number)
        if "=" in rest.split(None, 1)[0] or re.match(r"^[A-Z][A-Z0-9_]*\s*=", rest):
            cname, value = rest.split("=", 1)
            cname = cname.strip()
            if not _CONST_NAME.match(cname):
                raise MessageDefinitionError(source, number, cname,
                                             "constant names are UPPER_CASE")
            if not isinstance(type_, Primitive):
                raise MessageDefinitionError(source, number, type_text,
                                             "constants must have a primitive type")
            constants.append(Constant(cname, type_, _literal(type_, value, source, number)))
            continue
        fparts = rest.split(None, 1)
        fname = fparts[0]
        if not _FIELD_NAME.match(fname) or "__" in fname or fname.endswith("_"):
            raise MessageDefinitionError(source, number, fname,
                                         "field names are lower_case (letters, digits, _)")
        if fname in names:
            raise MessageDefinitionError(source, number, fname, "duplicate field name")
        names.add(fname)
        default = _literal(type_, fparts[1], source, number) if len(fparts) > 1 else None
        fields.append(Field(fname, type_, default, number))
    return MessageDef(name, fields, constants, str(source), first_line)


def _split_parts(text, count, source):
    parts, current, start, starts = [], [], 1, []
    for number, line in enumerate(text.splitlines(), start=1):
        if _SEPARATOR.match(line):
            parts.append("\n".join(current))
            starts.append(start)
            current, start = [], number + 1
        else:
            current.append(line)
    parts.append("\n".join(current))
    starts.append(start)
    if len(parts) != count:
        raise MessageDefinitionError(source, 0, None, f"expected {count - 1} '---' separator(s), "
                                     f"found {len(parts) - 1}")
    return list(zip(parts, starts))


#: name suffixes of the types ROS 2 generates for a service and an action (the C structs
#: ReconROS' ``rossrvmsg``/``rosactionmsg`` resources are)
SERVICE_REQUEST, SERVICE_RESPONSE = "_Request", "_Response"
ACTION_SEND_GOAL_REQUEST = "_SendGoal_Request"
ACTION_GET_RESULT_RESPONSE = "_GetResult_Response"
ACTION_FEEDBACK_MESSAGE = "_FeedbackMessage"


def parse_srv(text, name, source="<string>"):
    """``pkg/srv/Name`` -> [Name_Request, Name_Response]."""
    (req, l1), (res, l2) = _split_parts(text, 2, source)
    return [parse_msg(req, name + SERVICE_REQUEST, source, l1),
            parse_msg(res, name + SERVICE_RESPONSE, source, l2)]


def parse_action(text, name, source="<string>"):
    """``pkg/action/Name`` -> Goal, Result, Feedback and the five wire types of ROS 2."""
    (goal, l1), (result, l2), (feedback, l3) = _split_parts(text, 3, source)
    uuid = Named("unique_identifier_msgs/msg/UUID")
    defs = [parse_msg(goal, f"{name}_Goal", source, l1),
            parse_msg(result, f"{name}_Result", source, l2),
            parse_msg(feedback, f"{name}_Feedback", source, l3)]
    defs += [
        MessageDef(name + ACTION_SEND_GOAL_REQUEST,
                   [Field("goal_id", uuid), Field("goal", Named(f"{name}_Goal"))], [], source),
        MessageDef(f"{name}_SendGoal_Response",
                   [Field("accepted", Primitive("bool")),
                    Field("stamp", Named("builtin_interfaces/msg/Time"))], [], source),
        MessageDef(f"{name}_GetResult_Request", [Field("goal_id", uuid)], [], source),
        MessageDef(name + ACTION_GET_RESULT_RESPONSE,
                   [Field("status", Primitive("int8")),
                    Field("result", Named(f"{name}_Result"))], [], source),
        MessageDef(name + ACTION_FEEDBACK_MESSAGE,
                   [Field("goal_id", uuid), Field("feedback", Named(f"{name}_Feedback"))], [],
                   source),
    ]
    return defs


def parse_file(path, package=None):
    """Parse a ``.msg``, ``.srv`` or ``.action`` file; the package defaults to the folder above
    ``msg/``, ``srv/`` or ``action/``."""
    path = Path(path)
    kind = path.suffix[1:]
    if kind not in ("msg", "srv", "action"):
        raise MessageDefinitionError(path, 0, path.suffix, "not a .msg, .srv or .action file")
    if package is None:
        package = path.parent.parent.name if path.parent.name == kind else path.parent.name
    name = f"{package}/{kind}/{path.stem}"
    if not re.match(r"^[A-Z][A-Za-z0-9]*$", path.stem):
        raise MessageDefinitionError(path, 0, path.stem, "type names are CamelCase")
    text = path.read_text()
    if kind == "msg":
        return [parse_msg(text, name, path)]
    if kind == "srv":
        return parse_srv(text, name, path)
    return parse_action(text, name, path)
