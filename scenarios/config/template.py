"""`dynprop scenario-template [NAME]`: a scenario as annotated YAML, every key of the
schema with its value, its type and range, and its description (unit in
parentheses or in the key's name), generated from the schema as
docs/scenario-reference.md is (``reference``), so the two cannot drift.

Without NAME the values are the GOES-Next defaults; with a bundled NAME (or a YAML
path) they are that scenario's resolved values.  The text loads back to the same
scenario (tests/scenarios/test_scenario_template.py): a user copies it and deletes
or edits lines.
"""

from __future__ import annotations

import math
import textwrap

import yaml
from pydantic import BaseModel
from pydantic.fields import FieldInfo

from .reference import (
    ENTRY_KEY,
    _description,
    _intro,
    _tag_value,
    _type_cell,
    _variants,
    required_paths,
    yaml_text,
)
from .schema import Scenario

TEMPLATE_NAME = "my_scenario"   # the name a template of the defaults gets
WIDTH = 92                      # comment lines are wrapped here
INDENT = "  "


def _flow(value, nested: bool = False) -> str:
    """A value as one line of YAML that the loader reads back to the same value:
    numbers as their shortest text (``reference.yaml_text``), strings quoted by
    PyYAML wherever plain text would be read as something else; inside a flow
    collection (``nested``) also where a comma or bracket would end it (an event's
    label: "station keeping (10 N, ...)")."""
    if isinstance(value, str):
        text = yaml.safe_dump([value] if nested else value, default_flow_style=True,
                              allow_unicode=True, width=math.inf)
        text = text.removesuffix("\n").removesuffix("\n...")
        return text[1:-1] if nested else text
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_flow(k, True)}: {_flow(v, True)}"
                               for k, v in value.items()) + "}"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_flow(v, True) for v in value) + "]"
    return yaml_text(value)


def _comment(text: str, indent: str) -> list[str]:
    """``text`` as comment lines at ``indent``, wrapped (one line per paragraph
    when it fits)."""
    lines = []
    for paragraph in text.split("\n\n"):
        lines += textwrap.wrap(" ".join(paragraph.split()), WIDTH - len(indent) - 2,
                               break_on_hyphens=False) or [""]
    return [f"{indent}# {line}".rstrip() for line in lines]


def _entry_kinds(annotation, indent: str) -> list[str]:
    """Comment lines describing each kind of entry of a mapping like
    ``montecarlo.dispersions``: its keys, types and descriptions."""
    tag, models = _variants(annotation)
    lines = []
    for model in models:
        kind = _tag_value(model, tag)
        lines += _comment(f"an entry {ENTRY_KEY}: {{{tag}: {kind}, ...}}: {_intro(model)}",
                          indent)
        for name, f in model.model_fields.items():
            if name == tag:
                continue
            lines += _comment(f"  {name}: {_type_cell(f)}; {_description(f)}", indent)
    return lines


def _section(model: BaseModel, data: dict, prefix: str, indent: str,
             required: set[str]) -> list[str]:
    lines = []
    for name, f in type(model).model_fields.items():
        path = f"{prefix}{name}"
        value = getattr(model, name)
        if isinstance(value, BaseModel):
            lines += [""] + _section_head(type(value), f, indent)
            lines.append(f"{indent}{name}:")
            lines += _section(value, data[name], f"{path}.", indent + INDENT, required)
            continue
        # The reference's cell is markdown; a YAML comment needs neither its escapes
        # nor its code quotes.
        note = _type_cell(f).replace("\\|", "|").replace("`", "")
        if _variants(f.annotation):
            note = "mapping of entries of the kinds above"
        if path in required:
            note += ", required"
        lines += _comment(_description(f).replace("\\|", "|"), indent)
        if _variants(f.annotation):
            lines += _entry_kinds(f.annotation, indent)
        lines.append(f"{indent}{name}: {_flow(data[name])}   # {note}")
    return lines


def _section_head(model: type[BaseModel], field: FieldInfo, indent: str) -> list[str]:
    intro = _intro(model, field)
    return _comment(intro, indent) if intro else []


def template(scenario: Scenario | None = None) -> str:
    """The annotated YAML of ``scenario`` (default: the GOES-Next defaults, named
    ``TEMPLATE_NAME``)."""
    source = "the GOES-Next defaults" if scenario is None else f"scenario {scenario.name}"
    if scenario is None:
        scenario = Scenario(name=TEMPLATE_NAME)
    head = _comment(
        f"dynprop scenario: every key of the schema with the value of {source}. "
        "Above each key, what it means, its unit in parentheses at the end (or in the key's "
        "name; (-) is dimensionless); after it, its type and the range the schema enforces. "
        "A scenario file needs only the keys it changes: delete the rest and they take the "
        "GOES-Next defaults. docs/scenario-reference.md lists the same keys.", "")
    # model_dump(mode="json") gives each value as YAML holds it (tuples as lists, the
    # dispersions' models as mappings).
    data = scenario.model_dump(mode="json")
    body = _section(scenario, data, "", "", required_paths())
    return "\n".join(head + [""] + body) + "\n"
