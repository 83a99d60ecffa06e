"""`dynprop scenario-template [NAME]`: annotated YAML that loads back to the scenario it
shows, with every key of the schema and its description."""

from __future__ import annotations

import re

import pytest

from scenarios.cli import main
from scenarios.config.loader import bundled_names, load_scenario
from scenarios.config.schema import Scenario, leaf_paths

KEY_LINE = re.compile(r"^(?P<indent> *)(?P<key>[A-Za-z_][A-Za-z0-9_]*):(?P<rest>.*)$")


def _template(capsys, *args) -> str:
    assert main(["scenario-template", *args]) == 0
    captured = capsys.readouterr()
    assert captured.err == ""
    return captured.out


def _keys(text: str) -> dict[str, tuple[str, str]]:
    """Every key line of the template by its dotted path: (the comment lines right
    above it joined, the trailing comment), read from the indentation alone."""
    keys, stack, above = {}, [], []
    for line in text.splitlines():
        stripped = line.strip()
        if stripped.startswith("#"):
            above.append(stripped.lstrip("#").strip())
            continue
        m = KEY_LINE.match(line)
        if not m:
            above = []
            continue
        depth = len(m["indent"]) // 2
        stack = stack[:depth] + [m["key"]]
        value, _, trailing = m["rest"].partition("   # ")
        if value.strip():   # a value, not a section heading
            keys[".".join(stack)] = (" ".join(above), trailing.strip())
        above = []
    return keys


def _normal(text: str | None) -> str:
    return " ".join((text or "").split())


def _field(path: str):
    model = Scenario
    *sections, name = path.split(".")
    for part in sections:
        model = model.model_fields[part].annotation
    return model.model_fields[name]


def test_the_default_template_loads_back_to_the_defaults(capsys, tmp_path):
    path = tmp_path / "template.yaml"
    path.write_text(_template(capsys))
    # The schema's own defaults, under the template's placeholder name.
    assert load_scenario(str(path)).model_dump() == Scenario(name="my_scenario").model_dump()


@pytest.mark.parametrize("name", bundled_names())
def test_a_bundled_template_loads_back_to_that_scenario(name, capsys, tmp_path):
    path = tmp_path / f"{name}.yaml"
    path.write_text(_template(capsys, name))
    assert load_scenario(str(path)).model_dump() == load_scenario(name).model_dump()


def test_every_schema_key_appears_with_its_description_and_type(capsys):
    keys = _keys(_template(capsys))
    assert set(keys) == set(leaf_paths(Scenario))
    for path, (above, trailing) in keys.items():
        description = _normal(_field(path).description)
        # A new key without a description gives an empty comment here and fails.
        assert description, f"{path}: the schema gives no description"
        assert _normal(above).startswith(description), path
        assert trailing, f"{path}: no type after the value"
    assert keys["duration_s"][1] == "float, 0 < x ≤ 31622400.0"
    assert keys["name"][1].endswith("required")


def test_the_values_are_the_scenarios(capsys):
    """A moved key shows its new value (goes_next_mistrimmed: the tab at 16°); the
    default tab leaves 1e-6 N m of the 5e-5 N m imbalance at 2.5e-6 N m/deg, 19.6°."""
    text = _template(capsys, "goes_next_mistrimmed")
    assert re.search(r"^    trim_tab_deg: 16\.0   #", text, re.M)
    assert re.search(r"^name: goes_next_mistrimmed   #", text, re.M)
    assert re.search(r"^    trim_tab_deg: 19\.6   #", _template(capsys), re.M)


def test_an_unknown_name_is_one_line_exit_2(capsys):
    assert main(["scenario-template", "no_such_scenario"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no_such_scenario" in err[0]
