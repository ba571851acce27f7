"""The scenario reference (``docs/scenarios.md``), generated from the scenario dataclasses.

Every key of a scenario file is a field of ``station.scenario.Scenario`` or of a section dataclass
below it, and the comment next to the field (trailing it, or the comment lines directly above it)
is its documentation: this module reads those comments from the source and writes one table per
section (key, type, default, meaning). ``python -m sustain_drake.station.reference`` rewrites the
page; a test checks that the committed page is current.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import io
import math
import sys
import textwrap
import tokenize
import types
import typing
from pathlib import Path

from sustain_drake.files import write_atomically
from sustain_drake.station.scenario import Scenario

PAGE = Path(__file__).resolve().parents[2] / "docs" / "scenarios.md"
# Section types documented by Drake, not by us: a link instead of a table.
DRAKE_DOCS = {
    "CameraConfig": "https://drake.mit.edu/doxygen_cxx/structdrake_1_1systems_1_1sensors_1_1_camera_config.html",
    "LightParameter": "https://drake.mit.edu/doxygen_cxx/structdrake_1_1geometry_1_1_light_parameter.html",
    "MultibodyPlantConfig": "https://drake.mit.edu/doxygen_cxx/structdrake_1_1multibody_1_1_multibody_plant_config.html",
    "Transform": "https://drake.mit.edu/doxygen_cxx/classdrake_1_1schema_1_1_transform.html",
}


def field_comments(cls: type) -> dict[str, str]:
    """``{field: comment}`` for the fields a dataclass defines itself: the comment lines directly
    above the field and the comment trailing its last line, joined."""
    source = textwrap.dedent(inspect.getsource(cls))
    comments: dict[int, str] = {}
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type == tokenize.COMMENT:
            comments[token.start[0]] = token.string.lstrip("#").strip()
    lines = source.splitlines()
    found = {}
    body = ast.parse(source).body[0].body
    for node in body:
        if not (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)):
            continue
        above, row = [], node.lineno - 1
        while row >= 1 and row in comments and lines[row - 1].lstrip().startswith("#"):
            above.insert(0, comments[row])
            row -= 1
        trailing = [comments[r] for r in range(node.lineno, node.end_lineno + 1) if r in comments]
        text = " ".join(above + trailing).strip()
        if text:
            found[node.target.id] = text
    return found


def all_field_comments(cls: type) -> dict[str, str]:
    """``field_comments`` of a dataclass and of the dataclasses it derives from."""
    found = {}
    for base in reversed(cls.__mro__):
        if dataclasses.is_dataclass(base) and base is not object:
            found.update(field_comments(base))
    return found


def _type_name(t) -> str:
    origin = typing.get_origin(t)
    if origin in (typing.Union, types.UnionType):
        return " | ".join(_type_name(a) for a in typing.get_args(t))
    if origin is not None:
        return f"{origin.__name__}[{', '.join(_type_name(a) for a in typing.get_args(t))}]"
    return "None" if t is type(None) else getattr(t, "__name__", str(t))


def _default(value) -> str:
    if dataclasses.is_dataclass(value) or type(value).__name__ in DRAKE_DOCS:
        return "see below" if dataclasses.is_dataclass(value) else "a Drake type"
    if isinstance(value, float) and math.isinf(value):
        return ".inf" if value > 0 else "-.inf"
    if isinstance(value, bool):
        return "true" if value else "false"
    if value is None:
        return "null"
    return repr(value).replace("'", "")


def _section_types(t) -> list[type]:
    """The dataclasses (with a table of their own) inside a field's type."""
    args = typing.get_args(t)
    if args:
        return [c for a in args for c in _section_types(a)]
    return [t] if dataclasses.is_dataclass(t) else []


def _summary(cls: type) -> str:
    doc = inspect.getdoc(cls) or ""
    return " ".join(doc.split("\n\n")[0].split())


def sections(root: type = Scenario, key: str = "") -> list[tuple[str, type]]:
    """``(dotted key, dataclass)`` of every section under ``root``, depth first."""
    found = [(key, root)]
    hints = typing.get_type_hints(root)
    for f in dataclasses.fields(root):
        for cls in _section_types(hints[f.name]):
            if cls.__name__ in DRAKE_DOCS:
                continue
            is_variant = typing.get_origin(hints[f.name]) is list
            child = f"{key}.{f.name}" if key else f.name
            found += sections(cls, f"{child}[] !{cls.__name__}" if is_variant else child)
    return found


def missing_comments(root: type = Scenario) -> list[str]:
    """Keys whose field has no comment (each must have one)."""
    missing = []
    for key, cls in sections(root):
        comments = all_field_comments(cls)
        missing += [f"{key or '(top)'}.{f.name}" for f in dataclasses.fields(cls) if f.name not in comments]
    return missing


def reference_page(root: type = Scenario) -> str:
    """The whole Markdown page."""
    out = ["# Scenario reference", "",
           "Generated by `python -m sustain_drake.station.reference` from the comments next to the fields",
           "of `sustain_drake/station/scenario.py` and the sections it holds; do not edit by hand.",
           "A scenario file lists only what differs from these defaults; units are SI (m, s, rad, kg, N,",
           "N m) unless a key says px. A file holds one scenario, or several by name (`load_scenario`).",
           "Drake's own sections link to Drake's documentation: "
           + ", ".join(f"[{name}]({url})" for name, url in sorted(DRAKE_DOCS.items())) + ".", ""]
    for key, cls in sections(root):
        title = f"`{key}`" if key else "Top level"
        out += [f"## {title}", "", _summary(cls), "", "| key | type | default | meaning |",
                "|---|---|---|---|"]
        comments, hints, instance = all_field_comments(cls), typing.get_type_hints(cls), cls()
        for f in dataclasses.fields(cls):
            meaning = comments.get(f.name, "").replace("|", "\\|")
            type_name = _type_name(hints[f.name]).replace("|", "\\|")
            out.append(f"| `{f.name}` | {type_name} | {_default(getattr(instance, f.name))} "
                       f"| {meaning} |")
        out.append("")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Write the scenario reference page.")
    parser.add_argument("--out", type=Path, default=PAGE, help="the page (default %(default)s)")
    parser.add_argument("--check", action="store_true", help="exit 1 if the page is not current")
    args = parser.parse_args(argv)
    missing = missing_comments()
    if missing:
        print(f"fields without a comment: {', '.join(missing)}", file=sys.stderr)
        return 1
    page = reference_page()
    if args.check:
        current = args.out.is_file() and args.out.read_text(encoding="utf-8") == page
        print(f"{args.out}: {'current' if current else 'out of date'}")
        return 0 if current else 1
    write_atomically(args.out, page)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
