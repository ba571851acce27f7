"""Reading a scenario file before Drake does: duplicate keys, values of the wrong shape, and which
key a value ``yaml_load_typed`` refused belongs to (its messages name none). ``scenario.py``'s
loaders call these; every problem is a one-line ``ScenarioError`` naming the key."""

import dataclasses
import re
import types
import typing

import numpy as np
import yaml
from pydrake.common.yaml import yaml_load, yaml_load_typed

from sustain_drake.station.scenario import Scenario, ScenarioError, one_line


def check_duplicate_keys(text: str) -> None:
    """Refuses a key given twice in one mapping (YAML keeps the last one without a word); keys
    brought in by a merge (``<<: *base``) may be overridden."""
    try:
        root = yaml.compose(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
    except yaml.YAMLError as e:
        raise ScenarioError(f"not a readable YAML file ({one_line(e)})") from None
    seen: set[int] = set()
    stack = [(root, "")]
    while stack:
        node, path = stack.pop()
        if node is None or id(node) in seen:
            continue
        seen.add(id(node))
        if isinstance(node, yaml.SequenceNode):
            stack += [(item, f"{path}[{i}]") for i, item in enumerate(node.value)]
        elif isinstance(node, yaml.MappingNode):
            first: dict[str, int] = {}
            for key, value in node.value:
                if key.tag == "tag:yaml.org,2002:merge":
                    stack.append((value, path))
                    continue
                name = str(key.value) if isinstance(key, yaml.ScalarNode) else "?"
                where = f"{path}.{name}" if path else name
                line = key.start_mark.line + 1
                if name in first:
                    raise ScenarioError(f"duplicate key '{where}' on line {line} (first on line "
                                        f"{first[name]}): give each key once")
                first[name] = line
                stack.append((value, where))


class _RawLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):
    """Reads YAML as yaml_load_typed does (a tagged mapping gets a ``_tag`` item), with libyaml."""


def _construct_tagged(loader, tag, node):
    if not isinstance(node, yaml.MappingNode):
        raise yaml.constructor.ConstructorError(None, None, f"{tag} needs a mapping", node.start_mark)
    data = dict(loader.construct_mapping(node, deep=True))
    data["_tag"] = tag
    return data


_RawLoader.add_multi_constructor("!", _construct_tagged)


def raw_document(text: str):
    """The YAML ``text`` as plain data (None if it does not read: yaml_load_typed then says why)."""
    try:
        return yaml.load(text, Loader=_RawLoader)
    except Exception:  # noqa: BLE001
        return None


def shape_problem(value, schema, path: str) -> str | None:
    """A value yaml_load_typed would take in a wrong shape: a mapping or a number for a list (it reads
    a mapping's keys as the items), a number for a vector (it makes an uninitialized array of that
    size). None: no such value."""
    origin, args = typing.get_origin(schema), typing.get_args(schema)
    if origin in (typing.Union, types.UnionType):
        options = [a for a in args if a is not type(None)]
        if np.ndarray in options and value is not None and not isinstance(value, list | dict):
            return f"{path} needs a list of numbers, got {shown(value)}"
        if isinstance(value, dict) and "_tag" in value:
            match = [a for a in options if _tag_name(a) == str(value["_tag"]).lstrip("!")]
            return shape_problem(value, match[0], path) if match else None
        return shape_problem(value, options[0], path) if len(options) == 1 and value is not None else None
    if origin is list:
        if not isinstance(value, list):
            return f"{path} must be a list [...], got {shown(value)}"
        for i, item in enumerate(value):
            found = shape_problem(item, args[0], f"{path}[{i}]")
            if found:
                return found
        return None
    fields = schema_fields(schema)
    if fields is not None and isinstance(value, dict):
        for key, sub in value.items():
            if key in fields:
                found = shape_problem(sub, fields[key], f"{path}.{key}" if path else str(key))
                if found:
                    return found
    return None


class _TaggedDumper(getattr(yaml, "CSafeDumper", yaml.SafeDumper)):
    """Writes raw YAML data back as text, a ``_tag`` item as the mapping's tag (``!ToolSlip``)."""


def _represent_tagged(dumper, data):
    items = {k: v for k, v in data.items() if k != "_tag"}
    return dumper.represent_mapping(data.get("_tag", "tag:yaml.org,2002:map"), items)


_TaggedDumper.add_representer(dict, _represent_tagged)


def load_problem(text: str, name: str | None, error: Exception) -> str:
    """yaml_load_typed's ``error`` as one line naming the key (found by loading the document's
    values one at a time); Drake's own message when no single value is to blame."""
    try:
        document = yaml_load(data=text)
        root = document[name] if name is not None else document
        if root is None:
            return "the file holds no scenario: a scenario is a mapping of keys to values"
        if isinstance(root, dict):
            found = _value_problem(root, Scenario, "")
            if found:
                return found
    except Exception:  # noqa: BLE001 (only the message is at stake: keep Drake's)
        pass
    return one_line(error)


def schema_fields(schema) -> dict | None:
    if isinstance(schema, type) and dataclasses.is_dataclass(schema):
        return {f.name: f.type for f in dataclasses.fields(schema)}
    fields = getattr(schema, "__fields__", None)
    if isinstance(schema, type) and fields is not None:
        return {f.name: f.type for f in fields}
    return None


def _load_error(schema, data) -> Exception | None:
    """What yaml_load_typed says about the raw YAML ``data`` as a ``schema`` (None: it loads)."""
    try:
        yaml_load_typed(schema=schema, data=yaml.dump(data, Dumper=_TaggedDumper))
    except Exception as e:  # noqa: BLE001
        return e
    return None


def _probe_error(schema, value) -> Exception | None:
    """What yaml_load_typed says about ``value`` as a value of type ``schema`` (None: it loads)."""
    default = (dataclasses.field(default_factory=schema) if schema_fields(schema) is not None
               else dataclasses.field(default=None))
    return _load_error(dataclasses.make_dataclass("_Probe", [("value", schema, default)]), {"value": value})


def _value_problem(value, schema, path: str) -> str | None:
    """Why ``value`` cannot be loaded as ``schema``, naming the innermost key (None: it can)."""
    fields = schema_fields(schema)
    if fields is not None and isinstance(value, dict) and "_tag" not in value:
        for key, sub in value.items():
            where = f"{path}.{key}" if path else str(key)
            if key not in fields:
                return f"unknown key '{where}' (misspelled?)"
            error = _load_error(schema, {key: sub})  # this key alone, e.g. a Drake setter's check
            if error is not None:
                found = _value_problem(sub, fields[key], where)
                return found or f"{where} {_expected(fields[key], sub, error)}"
        return None
    error = _probe_error(schema, value)
    if error is None:
        return None
    origin, args = typing.get_origin(schema), typing.get_args(schema)
    if origin in (typing.Union, types.UnionType):
        options = [a for a in args if a is not type(None)]
        if value is not None and len(options) == 1:
            return _value_problem(value, options[0], path)
        if isinstance(value, dict) and "_tag" in value:
            tag = str(value["_tag"]).lstrip("!")
            match = [a for a in options if _tag_name(a) == tag]
            if not match:
                names = ", ".join("!" + _tag_name(a) for a in options if schema_fields(a) is not None)
                return f"{path}: unknown tag !{tag} (expected one of {names})"
            return _value_problem({k: v for k, v in value.items() if k != "_tag"}, match[0], path)
    elif origin is list and isinstance(value, list):
        for i, item in enumerate(value):
            found = _value_problem(item, args[0], f"{path}[{i}]")
            if found:
                return found
    elif fields is not None and isinstance(value, dict):
        return f"{path}: a tag ({value['_tag']}) is not allowed here"
    return f"{path} {_expected(schema, value, error)}"


def _tag_name(schema) -> str:
    return getattr(schema, "__name__", str(schema)).split("[", 1)[0].split("𝓣", 1)[0]


def _expected(schema, value, error: Exception) -> str:
    """``must be ...`` for a value of the wrong type or length."""
    size = re.search(r"float64\[(\d+), 1\]", str(error))
    if size:
        return f"needs {size.group(1)} numbers, got {shown(value)}"
    words = {float: "a number", int: "a whole number", bool: "true or false", str: "text"}
    if schema in words:
        return f"must be {words[schema]}, got {shown(value)}"
    if typing.get_origin(schema) is list:
        return f"must be a list [...], got {shown(value)}"
    if schema_fields(schema) is not None:
        return f"must be a mapping of keys to values, got {shown(value)}"
    return f"has a wrong value {shown(value)} ({one_line(error)})"


def shown(value) -> str:
    """A value for a message: short, one line."""
    if isinstance(value, int | np.integer) and not isinstance(value, bool) and int(value).bit_length() > 64:
        return "a very large integer"
    if isinstance(value, float | np.floating):
        return f"{float(value):g}"
    if isinstance(value, list | tuple | np.ndarray) and all(
            isinstance(v, int | float | np.number) and not isinstance(v, bool) for v in value):
        return "[" + ", ".join(shown(v) for v in value) + "]"
    text = " ".join(repr(value).split())
    return text if len(text) <= 60 else text[:57] + "..."
