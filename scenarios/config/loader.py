"""Load, override and validate scenarios (``schema.resolved_yaml`` writes them back).

Every failure is a ``ScenarioError`` holding every problem found, one line each,
and each line names the key path (or the file) and, for a misspelt key, the
closest valid key.  The CLI prints them before exiting with status 2.
"""

from __future__ import annotations

import re
import typing
from importlib import resources
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ValidationError

from .montecarlo import DISTRIBUTION_TAGS, Normal, Uniform
from .schema import Scenario
from .suggestions import cap_lines, did_you_mean


class ScenarioError(ValueError):
    """A bad scenario: one line per problem, each naming its key path (or the file)."""

    @property
    def problems(self) -> list[str]:
        return str(self).splitlines()


class _Loader(yaml.SafeLoader):
    """SafeLoader that keeps ISO timestamps as strings (epoch_utc is validated as
    text) and refuses duplicate keys instead of silently keeping the last."""


_Loader.yaml_implicit_resolvers = {
    first: [(tag, rx) for tag, rx in resolvers if tag != "tag:yaml.org,2002:timestamp"]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
# YAML 1.1 needs a dot in a float ("1e-6" would be a string); accept the YAML 1.2 /
# JSON forms that analysts write, such as 1e-6, 5E-5 and 6e1.
_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"))


class _DuplicateKey(Exception):
    pass


def _mapping(loader: _Loader, node: yaml.MappingNode, deep: bool = False) -> dict:
    seen = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            mark = key_node.start_mark
            raise _DuplicateKey(f":{mark.line + 1}:{mark.column + 1}: duplicate key {key!r}")
        seen.add(key)
    return loader.construct_mapping(node, deep=deep)


def _no_set(loader: _Loader, node: yaml.Node):
    # A YAML set has no order: it would silently scramble a vector's components.
    raise _DuplicateKey(f":{node.start_mark.line + 1}:{node.start_mark.column + 1}: "
                        "!!set is not allowed; use a list")


_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _mapping)
_Loader.add_constructor("tag:yaml.org,2002:set", _no_set)


def bundled_dir() -> Path:
    return Path(str(resources.files("dynprop.scenarios").joinpath("bundled")))


def bundled_names() -> list[str]:
    return sorted(p.stem for p in bundled_dir().glob("*.yaml"))


def _parse_yaml(text: str, where: str) -> Any:
    try:
        return yaml.load(text, Loader=_Loader)  # noqa: S506 - a SafeLoader subclass
    except _DuplicateKey as exc:
        raise ScenarioError(f"{where}{exc}") from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        pos = f":{mark.line + 1}:{mark.column + 1}" if mark else ""
        raise ScenarioError(f"{where}{pos}: YAML syntax error: {exc.problem}") from None
    except yaml.YAMLError as exc:
        raise ScenarioError(f"{where}: YAML error: {exc}") from None


def read_raw(source: str | Path) -> tuple[dict, str]:
    """The raw mapping of a scenario file or bundled name, and where it came from."""
    path = Path(source)
    if not path.exists() and str(source) in bundled_names():
        path = bundled_dir() / f"{source}.yaml"
    if not path.is_file():
        names = ", ".join(bundled_names())
        raise ScenarioError(f"scenario {source}: no such file or bundled scenario "
                            f"(bundled: {names})")
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError(f"scenario {source}: cannot read: {exc}") from None
    raw = _parse_yaml(text, str(path))
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise ScenarioError(f"{path}: the top level must be a mapping of keys")
    return raw, str(path)


def apply_override(raw: dict, assignment: str) -> None:
    """Apply ``key.path=value`` in place; the value is read as YAML (``7``, ``true``,
    ``[1, 2, 3]``, ``1e-6``), so types are checked like the file's."""
    if "=" not in assignment:
        raise ScenarioError(f"--set {assignment}: expected key.path=value")
    path, text = assignment.split("=", 1)
    keys = path.strip().split(".")
    if not all(keys):
        raise ScenarioError(f"--set {assignment}: empty key in {path!r}")
    node = raw
    for i, key in enumerate(keys[:-1]):
        child = node.setdefault(key, {})
        if not isinstance(child, dict):
            raise ScenarioError(f"{'.'.join(keys[:i + 1])}: is a value, cannot set "
                                f"{path} inside it")
        node = child
    node[keys[-1]] = _parse_yaml(text, f"--set {path}")


def _union_label(part) -> bool:
    return isinstance(part, str) and (part in DISTRIBUTION_TAGS or part == "float"
                                      or part.startswith("tuple["))


def _model_at(loc: tuple) -> type[BaseModel] | None:
    """The schema model that holds the key at ``loc`` (its parent), or None where
    the keys are the user's own (the dispersion mapping)."""
    model: Any = Scenario
    parts = list(loc[:-1])
    while parts:
        part = parts.pop(0)
        if part in DISTRIBUTION_TAGS:
            model = {"normal": Normal, "uniform": Uniform}[part]
            continue
        if not (isinstance(model, type) and issubclass(model, BaseModel)) \
                or part not in model.model_fields:
            return None
        model = model.model_fields[part].annotation
        if typing.get_origin(model) is dict:
            if not parts:
                return None
            parts.pop(0)  # the user's key (a dispersed key path)
            model = None
    return model if isinstance(model, type) and issubclass(model, BaseModel) else None


def problem_lines(exc: ValidationError) -> list[str]:
    """One line per problem key, each starting with its key path; an unknown key
    names the closest valid key at the same place.  A vector or matrix with several
    bad elements is one problem: its first element is shown, with the count."""
    lines: dict[str, list[str]] = {}
    for error in exc.errors():
        # Union labels in a dispersion's loc ("...normal.sigma.float") are not keys
        # the user wrote; a union gives one error per alternative, keep the first.
        loc = tuple(p for p in error["loc"] if not _union_label(p))
        first_int = next((i for i, p in enumerate(loc) if isinstance(p, int)), len(loc))
        where = ".".join(str(p) for p in loc[:first_int])
        index = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in loc[first_int:])
        msg = error["msg"].removeprefix("Value error, ")
        if error["type"] == "extra_forbidden":
            model = _model_at(error["loc"])
            msg = "unknown key" + (did_you_mean(str(loc[-1]), model.model_fields)
                                   if model is not None else "")
        elif error["type"] == "missing":
            msg = "missing value (wrong length)" if isinstance(error["loc"][-1], int) \
                else "required key is missing"
        if not where:
            # Whole-scenario checks (the Monte Carlo keys) name their key paths
            # themselves, one line each.
            for line in msg.splitlines():
                lines.setdefault(line if ": " in line else f"scenario: {line}", [])
            continue
        lines.setdefault(where, []).append(f"{msg} at {index}" if index else msg)
    out = []
    for where, msgs in lines.items():
        if not msgs:
            out.append(where)
            continue
        more = len(msgs) - 1
        out.append(f"{where}: {msgs[0]}" + (f" (and {more} more in this value)" if more else ""))
    return out


def format_error(exc: ValidationError) -> str:
    """Every problem, one line each (at most MAX_PROBLEM_LINES)."""
    return "\n".join(cap_lines(problem_lines(exc)))


def validate(raw: dict) -> Scenario:
    try:
        return Scenario.model_validate(raw)
    except ValidationError as exc:
        raise ScenarioError(format_error(exc)) from None


def load_scenario(source: str | Path, overrides: list[str] = ()) -> Scenario:
    """The validated scenario with ``key.path=value`` overrides applied in order.
    Every problem of the file and of the overrides is reported together."""
    raw, _ = read_raw(source)
    problems: list[str] = []
    for assignment in overrides:
        try:
            apply_override(raw, assignment)
        except ScenarioError as exc:
            problems += exc.problems
    try:
        scenario = validate(raw)
    except ScenarioError as exc:
        problems += exc.problems
    if problems:
        raise ScenarioError("\n".join(cap_lines(problems)))
    return scenario
