"""Render docs/scenario-reference.md from the schema, so the two cannot drift.

    python -m scenarios.reference > docs/scenario-reference.md

A test compares the committed file with ``render()``.
"""

from __future__ import annotations

import typing

from pydantic import BaseModel

from .schema import Scenario

HEADER = """# Scenario reference

Generated from `scenarios/schema.py` by `python -m scenarios.reference`; do not edit.

A scenario is a YAML mapping. Every key is optional except `name`, and omitted
keys take the GOES-Next defaults below (from the paper unless the description
says otherwise). Unknown keys, wrong types, NaN and infinity are errors, and
`dynprop` names the key path of the first problem and exits with status 2.
Any key can be overridden from the command line with `--set key.path=value`
(the value is read as YAML: `--set control.enabled=false`,
`--set initial_state.rate_wrt_orbit_degps=[0.001,0,0]`). Units are in the key
names or in parentheses at the end of each description.
"""


def _type_name(annotation) -> str:
    origin = typing.get_origin(annotation)
    if origin is typing.Annotated:
        return _type_name(typing.get_args(annotation)[0])
    if origin is typing.Literal:
        return " \\| ".join(f"`{a}`" for a in typing.get_args(annotation))
    if origin is tuple:
        args = typing.get_args(annotation)
        inner = _type_name(args[0])
        return "3×3 list of float" if inner.startswith("list") else f"list of {len(args)} {inner}"
    if origin in (typing.Union, getattr(__import__("types"), "UnionType", None)):
        return " or ".join(_type_name(a) for a in typing.get_args(annotation))
    return getattr(annotation, "__name__", str(annotation)).replace("NoneType", "null")


def _value(v) -> str:
    if isinstance(v, bool):
        return f"`{str(v).lower()}`"
    if isinstance(v, tuple):
        return "`" + str([list(r) if isinstance(r, tuple) else r for r in v]) + "`"
    if v is None:
        return "`null`"
    if v == "":
        return '`""`'
    return f"`{v}`"


def _section(model: BaseModel, prefix: str, lines: list[str]) -> None:
    rows, subs = [], []
    for name, field in type(model).model_fields.items():
        value = getattr(model, name)
        if isinstance(value, BaseModel):
            subs.append((f"{prefix}{name}", value, field.description))
            continue
        default = "(required)" if field.is_required() else _value(value)
        desc = (field.description or "").replace("|", "\\|")
        rows.append(f"| `{prefix}{name}` | {_type_name(field.annotation)} | {default} | {desc} |")
    if rows:
        title = prefix.rstrip(".") or "top level"
        lines += ["", f"## `{title}`", ""]
        doc = (type(model).__doc__ or "").strip()
        if doc and prefix:
            lines += [doc.splitlines()[0], ""]
        lines += ["| key | type | default | description (unit) |", "|---|---|---|---|", *rows]
    for path, value, _ in subs:
        _section(value, f"{path}.", lines)


def render() -> str:
    lines = [HEADER.rstrip()]
    _section(Scenario(name="example"), "", lines)
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(render(), end="")
