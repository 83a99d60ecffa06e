"""Render docs/scenario-reference.md from the schema, so the two cannot drift.

    python -m dynprop.scenarios.config.reference --out docs/scenario-reference.md  # make docs
    python -m dynprop.scenarios.config.reference --check docs/scenario-reference.md  # stale: 1
    python -m dynprop.scenarios.config.reference                                   # to stdout

Everything in the document is read from the schema, not restated:

* a key's default is its value in the default scenario, so keys whose defaults come
  from their section (the Sun-sensor heads, filled per head by ``SunSensors``) show
  the value a scenario really gets;
* a key is "(required)" only if the schema rejects a scenario that leaves it out
  (found by validating scenarios that omit it, not from the field alone);
* bounds (``gt``, ``le``, ``min_length``) are printed from the field's constraints,
  and a section's text is its model's whole docstring.

tests/scenarios/test_scenario_reference.py checks the committed file against
``render()`` and checks every row against the schema and the loader.
"""

from __future__ import annotations

import argparse
import inspect
import sys
import types
import typing
from dataclasses import dataclass
from pathlib import Path

import annotated_types as at
from pydantic import BaseModel, ValidationError
from pydantic.fields import FieldInfo
from pydantic.types import Strict

from .schema import Scenario
from .suggestions import MAX_PROBLEM_LINES

HEADER = """# Scenario reference

Generated from the schema (`scenarios/config/`) by `python -m
dynprop.scenarios.config.reference --out docs/scenario-reference.md` (`make docs`); do not edit.

A scenario is a YAML mapping.
{required}
Omitted keys take the GOES-Next defaults below (from the paper unless the description
says otherwise). Unknown keys, wrong types, values out of range, NaN and infinity are
errors: `dynprop` prints one line per problem (at most {max_lines}), each starting with
the key path and, for a misspelt key, naming the closest valid key, and exits with
status 2.
Any key can be overridden from the command line with `--set key.path=value`
(the value is read as YAML: `--set control.enabled=false`,
`--set initial_state.rate_wrt_orbit_degps=[0.001,0,0]`). Units are in the key
names or in parentheses at the end of each description; `(-)` means dimensionless.
The type column gives the range the schema enforces, if any.
"""

REQUIRED = "(required)"
# A dispersion-style mapping's user-chosen key, as shown in key paths.
ENTRY_KEY = "<key>"
# An entry of a list of sections (``events``), as shown in key paths.
ENTRY_INDEX = "<i>"


@dataclass(frozen=True)
class Key:
    """One table row."""

    path: str
    type: str
    default: str  # the YAML text of the default, or REQUIRED
    description: str


@dataclass(frozen=True)
class Section:
    """One heading, its text (the model's whole docstring) and its keys."""

    path: str  # "" for the top level
    title: str
    intro: str
    keys: tuple[Key, ...]


# --------------------------------------------------------------------------- values


def _number(v: float | int) -> str:
    """The shortest text that reads back (YAML 1.2) to the same number: ``5e-5``, not
    Python's ``5e-05``."""
    if isinstance(v, int):
        return str(v)
    text = repr(float(v))
    mantissa, e, exponent = text.partition("e")
    return f"{mantissa}e{int(exponent)}" if e else text


def yaml_text(v) -> str:
    """A default as the YAML a user would write for it."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if v is None:
        return "null"
    if isinstance(v, int | float):
        return _number(v)
    if isinstance(v, str):
        return v if v else '""'
    if isinstance(v, tuple | list):
        return "[" + ", ".join(yaml_text(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k}: {yaml_text(x)}" for k, x in v.items()) + "}"
    raise TypeError(f"no YAML text for a default of type {type(v).__name__}")


# --------------------------------------------------------------------------- types


def _is_model(annotation) -> bool:
    return isinstance(annotation, type) and issubclass(annotation, BaseModel)


def _variants(annotation) -> tuple[str, tuple[type[BaseModel], ...]] | None:
    """(discriminator, models) if ``annotation`` is a mapping of user keys to a
    discriminated union of models (``montecarlo.dispersions``), else None."""
    if typing.get_origin(annotation) is not dict:
        return None
    value = typing.get_args(annotation)[1]
    if typing.get_origin(value) is not typing.Annotated:
        return None
    union, *meta = typing.get_args(value)
    tags = [m.discriminator for m in meta if isinstance(m, FieldInfo) and m.discriminator]
    models = typing.get_args(union)
    if not tags or not all(_is_model(m) for m in models):
        return None
    return tags[0], models


def _list_of(annotation) -> type[BaseModel] | None:
    """The section of each entry if ``annotation`` is a list of sections (``events``)."""
    if typing.get_origin(annotation) is typing.Annotated:
        annotation = typing.get_args(annotation)[0]
    args = typing.get_args(annotation)
    if typing.get_origin(annotation) is tuple and len(args) == 2 and args[1] is Ellipsis \
            and _is_model(args[0]):
        return args[0]
    return None


def _type_name(annotation) -> str:
    origin = typing.get_origin(annotation)
    if _list_of(annotation):
        return "list of entries (below)"
    if origin is typing.Annotated:
        return _type_name(typing.get_args(annotation)[0])
    if origin is typing.Literal:
        return " \\| ".join(f"`{str(a).lower() if isinstance(a, bool) else a}`"
                             for a in typing.get_args(annotation))
    if origin is tuple:
        args = typing.get_args(annotation)
        inner = _type_name(args[0])
        if inner.startswith("list of"):
            return f"{len(args)}×{inner.split()[2]} list of floats"
        return f"list of {len(args)} {inner}s"
    if origin is list:
        return f"list of {_type_name(typing.get_args(annotation)[0])}"
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(annotation)
        if type(None) in args and len(args) > 1:   # an optional value: null is allowed
            return " or ".join([_type_name(a) for a in args if a is not type(None)] + ["null"])
        return " or ".join(_type_name(a) for a in args)
    if _variants(annotation):
        return "mapping (entries below)"
    if annotation in (None, type(None)):
        return "any (ignored)"
    if annotation in (str, int, float, bool):
        return annotation.__name__
    raise TypeError(f"no documented name for the type {annotation!r}")


def _range(field: FieldInfo) -> str:
    """The constraints on the field, as the schema enforces them: ``> 0``,
    ``0 ≤ x < 90``, ``not empty``."""
    lower = upper = None
    words = []
    for m in field.metadata:
        if isinstance(m, at.Gt):
            lower = f"{_number(m.gt)} <"
        elif isinstance(m, at.Ge):
            lower = f"{_number(m.ge)} ≤"
        elif isinstance(m, at.Lt):
            upper = f"< {_number(m.lt)}"
        elif isinstance(m, at.Le):
            upper = f"≤ {_number(m.le)}"
        elif isinstance(m, at.MinLen) and m.min_length == 1:
            words.append("not empty")
        elif not isinstance(m, Strict):
            # A constraint this generator cannot print would silently go undocumented.
            raise TypeError(f"undocumented constraint {m!r}")
    if lower and upper:
        words.insert(0, f"{lower} x {upper}")
    elif lower:
        bound, op = lower.split()
        words.insert(0, f"{'>' if op == '<' else '≥'} {bound}")
    elif upper:
        words.insert(0, upper)
    return ", ".join(words)


def _type_cell(field: FieldInfo) -> str:
    name, bounds = _type_name(field.annotation), _range(field)
    if not bounds:
        return name
    return f"{name} {bounds}" if bounds[0] in "<>≤≥" else f"{name}, {bounds}"


# --------------------------------------------------------------------------- required


def _empty_sections(model: type[BaseModel]) -> dict:
    """Every section of ``model`` given, as an empty mapping, and no value."""
    return {name: _empty_sections(f.annotation) for name, f in model.model_fields.items()
            if _is_model(f.annotation)}


def _missing(raw: dict) -> set[tuple]:
    try:
        Scenario.model_validate(raw)
    except ValidationError as exc:
        return {tuple(e["loc"]) for e in exc.errors() if e["type"] == "missing"}
    return set()


def required_paths() -> set[str]:
    """Key paths a scenario must give: those the schema reports missing when every key
    is left out, whether their sections are left out or given empty (a section may
    fill its keys from its own defaults, as the Sun-sensor heads do).  Inside a
    mapping of entries (``montecarlo.dispersions``), the keys an entry of each kind
    must give, and the discriminator that names the kind."""
    missing = _missing({}) | _missing(_empty_sections(Scenario))
    paths = {".".join(map(str, loc)) for loc in missing}
    for prefix, (tag, models) in _entry_mappings(Scenario, ""):
        for model in models:
            kind = _tag_value(model, tag)
            raw: dict = {}
            node = raw
            for part in prefix.split("."):
                node = node.setdefault(part, {})
            node[ENTRY_KEY] = {tag: kind}
            paths.add(f"{prefix}.{ENTRY_KEY}.{tag}")
            for loc in _missing(raw):
                # the union's kind appears in the location; the user does not write it
                parts = [str(p) for p in loc if p != kind]
                if ".".join(parts).startswith(f"{prefix}.{ENTRY_KEY}."):
                    paths.add(".".join(parts))
    for name, f in Scenario.model_fields.items():
        if _list_of(f.annotation):
            # An empty entry: the keys every entry must give.
            paths |= {".".join(ENTRY_INDEX if isinstance(p, int) else str(p) for p in loc)
                      for loc in _missing({name: [{}]}) if loc[:2] == (name, 0)}
    return paths


def _entry_mappings(model: type[BaseModel], prefix: str):
    for name, f in model.model_fields.items():
        if _is_model(f.annotation):
            yield from _entry_mappings(f.annotation, f"{prefix}{name}.")
        elif _variants(f.annotation):
            yield f"{prefix}{name}", _variants(f.annotation)


def _tag_value(model: type[BaseModel], tag: str) -> str:
    (value,) = typing.get_args(model.model_fields[tag].annotation)
    return value


# --------------------------------------------------------------------------- sections


def _intro(model: type[BaseModel], field: FieldInfo | None = None) -> str:
    """The model's whole docstring (or else its field's description), one paragraph
    per paragraph of the source, its lines joined."""
    text = model.__doc__ or (field.description if field is not None else None) or ""
    paragraphs = inspect.cleandoc(text).split("\n\n") if text else []
    return "\n\n".join(" ".join(p.split()).replace("``", "`") for p in paragraphs)


def _description(field: FieldInfo) -> str:
    return " ".join((field.description or "").split()).replace("|", "\\|")


def _walk(model: BaseModel, field: FieldInfo | None, prefix: str, required: set[str],
          out: list[Section]) -> None:
    keys, subs, entries = [], [], []
    for name, f in type(model).model_fields.items():
        path = f"{prefix}{name}"
        value = getattr(model, name)
        if isinstance(value, BaseModel):
            subs.append((value, f, f"{path}."))
            continue
        default = REQUIRED if path in required else yaml_text(value)
        keys.append(Key(path, _type_cell(f), default, _description(f)))
        if _variants(f.annotation):
            entries.append((path, *_variants(f.annotation)))
        if _list_of(f.annotation):
            entries.append((path, None, (_list_of(f.annotation),)))
    intro = _intro(type(model), field)
    if keys or intro:
        title = f"`{prefix.rstrip('.')}`" if prefix else "Top level"
        out.append(Section(prefix.rstrip("."), title, intro, tuple(keys)))
    for path, tag, models in entries:
        if tag is None:       # a list's entries
            (m,) = models
            base = f"{path}.{ENTRY_INDEX}."
            rows = tuple(Key(f"{base}{n}", _type_cell(f), REQUIRED if f"{base}{n}" in required
                             else yaml_text(f.get_default(call_default_factory=True)),
                             _description(f)) for n, f in m.model_fields.items())
            out.append(Section(f"{path}.{ENTRY_INDEX}", f"`{path}` entries", _intro(m), rows))
            continue
        for m in models:
            kind = _tag_value(m, tag)
            base = f"{path}.{ENTRY_KEY}."
            rows = tuple(
                Key(f"{base}{n}", _type_cell(f),
                    REQUIRED if f"{base}{n}" in required else
                    yaml_text(f.get_default(call_default_factory=True)),
                    _description(f))
                for n, f in m.model_fields.items())
            out.append(Section(f"{path}.{ENTRY_KEY}", f"`{path}.{ENTRY_KEY}` with "
                               f"`{tag}: {kind}`", _intro(m), rows))
    for value, f, path in subs:
        _walk(value, f, path, required, out)


def sections() -> list[Section]:
    required = required_paths()
    # `name` has no default; the placeholder is never printed (it is "(required)").
    out: list[Section] = []
    _walk(Scenario(name="example"), None, "", required, out)
    return out


def _header(all_sections: list[Section]) -> str:
    plain = [k.path for s in all_sections for k in s.keys
             if k.default == REQUIRED and ENTRY_KEY not in k.path]
    plain = [p for p in plain if ENTRY_INDEX not in p]
    entry = sorted({s.path for s in all_sections for k in s.keys
                    if k.default == REQUIRED and (ENTRY_KEY in k.path or ENTRY_INDEX in k.path)})
    text = "Every key is optional except " + ", ".join(f"`{p}`" for p in plain)
    if entry:
        text += ", and the keys marked " + REQUIRED + " in each entry of " + \
            ", ".join(f"`{p.removesuffix('.' + ENTRY_KEY).removesuffix('.' + ENTRY_INDEX)}`"
                      for p in entry)
    return HEADER.format(required=text + ".", max_lines=MAX_PROBLEM_LINES)


def render() -> str:
    all_sections = sections()
    lines = [_header(all_sections).rstrip()]
    for s in all_sections:
        lines += ["", f"## {s.title}", ""]
        if s.intro:
            lines += [s.intro, ""]
        if s.keys:
            lines += ["| key | type | default | description (unit) |", "|---|---|---|---|"]
            for k in s.keys:
                default = k.default if k.default == REQUIRED else f"`{k.default}`"
                lines.append(f"| `{k.path}` | {k.type} | {default} | {k.description} |")
        elif lines[-1] == "":
            lines.pop()
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m dynprop.scenarios.config.reference",
                                     description=__doc__.splitlines()[0])
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--out", type=Path, help="write the document here")
    group.add_argument("--check", type=Path, help="exit 1 if this file is not current")
    args = parser.parse_args(argv)
    text = render()
    if args.check:
        if not args.check.exists() or args.check.read_text() != text:
            print(f"{args.check} is stale: regenerate with `python -m "
                  f"dynprop.scenarios.config.reference --out {args.check}` (or `make docs`)",
                  file=sys.stderr)
            return 1
        return 0
    if args.out:
        # Written whole or not at all: a failed render never leaves a truncated file.
        tmp = args.out.with_name(f".{args.out.name}.tmp")
        tmp.write_text(text)
        tmp.replace(args.out)
        return 0
    sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
