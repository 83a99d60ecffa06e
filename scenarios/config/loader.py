"""Load, override and validate scenarios (``schema.resolved_yaml`` writes them back).

Every failure is a ``ScenarioError`` holding every problem found, one line each,
and each line names the key path (or the file) and, for a misspelt key, the
closest valid key.  The CLI prints them before exiting with status 2.
"""

from __future__ import annotations

import re
import types
import typing
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ValidationError

from .montecarlo import DISTRIBUTION_TAGS, Normal, Uniform
from .schema import Scenario
from .suggestions import cap_lines, closest, did_you_mean, shown


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
    raw, where, _ = _read_source(source)
    return raw, where


def _read_source(source: str | Path) -> tuple[dict, str, str]:
    """``read_raw``, and the file's text (for the line of each key in messages)."""
    path = Path(source)
    # A bundled name is the bundled file unless a file of that name is here (a folder
    # named like it, a run's --out, does not shadow it).
    if not path.is_file() and str(source) in bundled_names():
        path = bundled_dir() / f"{source}.yaml"
    if not path.is_file():
        names = bundled_names()
        # A bare name is a bundled one mistyped (goes_next_equinx): name the likely one.
        match = closest(str(source), names) if len(path.parts) == 1 else None
        hint = (f"did you mean '{match}'? (`dynprop scenarios` lists them)" if match
                else f"bundled: {', '.join(names)}")
        raise ScenarioError(f"scenario {source}: no such file or bundled scenario; {hint}")
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError(f"scenario {source}: cannot read: {exc}") from None
    raw = _parse_yaml(text, str(path))
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise ScenarioError(f"{path}: the top level must be a mapping of keys")
    return raw, str(path), text


def apply_override(raw: dict, assignment: str, origin: str | None = None) -> None:
    """Apply ``key.path=value`` in place; the value is read as YAML (``7``, ``true``,
    ``[1, 2, 3]``, ``1e-6``), so types are checked like the file's.  ``origin``: the
    option that gave it, for messages (default ``--set key.path=value``)."""
    if "=" not in assignment:
        raise ScenarioError(f"{origin or '--set ' + assignment}: expected key.path=value")
    path, text = assignment.split("=", 1)
    keys = path.strip().split(".")
    if not all(keys):
        raise ScenarioError(f"{origin or '--set ' + assignment}: empty key in {path!r}")
    node = raw
    for i, key in enumerate(keys):
        # An entry of a list by its index (events.0.time_s), as Monte Carlo keys are.
        if isinstance(node, list):
            if not (key.isdigit() and int(key) < len(node)):
                raise ScenarioError(f"{'.'.join(keys[:i])}: has {len(node)} entries, no "
                                    f"entry {key} to set {path} in")
            key = int(key)
        elif not isinstance(node, dict):
            raise ScenarioError(f"{'.'.join(keys[:i])}: is a value, cannot set "
                                f"{path} inside it")
        if i == len(keys) - 1:
            node[key] = _parse_yaml(text, origin or f"--set {path}")
            return
        node = node.setdefault(key, {}) if isinstance(node, dict) else node[key]


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
        if typing.get_origin(model) is typing.Annotated:
            model = typing.get_args(model)[0]
        if typing.get_origin(model) is tuple and parts and isinstance(parts[0], int):
            parts.pop(0)  # an entry of a list of sections (events[3])
            model = typing.get_args(model)[0]
        if typing.get_origin(model) is dict:
            if not parts:
                return None
            parts.pop(0)  # the user's key (a dispersed key path)
            model = None
    return model if isinstance(model, type) and issubclass(model, BaseModel) else None


@dataclass(frozen=True)
class Sources:
    """Where each key's value came from, for messages: the scenario file (with the
    line of each key) or the option that overrode it (``--set key=value``,
    ``--duration-s 600``), the later overrides winning."""

    path: str | None = None
    lines: dict[tuple, int] = field(default_factory=dict)
    overrides: tuple[tuple[tuple, str], ...] = ()

    def of(self, keys: tuple) -> str | None:
        for set_keys, origin in reversed(self.overrides):
            n = min(len(set_keys), len(keys))
            if set_keys[:n] == keys[:n]:
                return origin
        if self.path is None:
            return None
        line = next((self.lines[keys[:k]] for k in range(len(keys), 0, -1)
                     if keys[:k] in self.lines), None)
        return self.path if line is None else f"{self.path}:{line}"


def key_lines(text: str) -> dict[tuple, int]:
    """The line (from 1) of every mapping key of a YAML text, by its key path."""
    try:
        root = yaml.compose(text, Loader=_Loader)
    except yaml.YAMLError:
        return {}
    lines: dict[tuple, int] = {}

    def walk(node, prefix: tuple) -> None:
        if isinstance(node, yaml.MappingNode):
            for key, value in node.value:
                if isinstance(key, yaml.ScalarNode):
                    lines.setdefault(prefix + (key.value,), key.start_mark.line + 1)
                    walk(value, prefix + (key.value,))
        elif isinstance(node, yaml.SequenceNode):
            # The entries of a list of sections (events), by index.
            for i, item in enumerate(node.value):
                if isinstance(item, yaml.MappingNode):
                    lines.setdefault(prefix + (i,), item.start_mark.line + 1)
                    walk(item, prefix + (i,))
    walk(root, ())
    return lines


def _value_at(raw, keys: tuple):
    node = raw
    for key in keys:
        if isinstance(node, list) and isinstance(key, int) and 0 <= key < len(node):
            node = node[key]
            continue
        if not isinstance(node, dict) or key not in node:
            return _ABSENT
        node = node[key]
    return node


_ABSENT = object()


def _shape(annotation) -> str | None:
    """A vector or matrix field's shape in the user's words ("a list of 3 numbers")."""
    if typing.get_origin(annotation) is typing.Annotated:
        annotation = typing.get_args(annotation)[0]
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        # An optional vector (an event's torque_Nm): the vector's shape.
        inner = [a for a in typing.get_args(annotation) if a is not type(None)]
        return _shape(inner[0]) if len(inner) == 1 else None
    if typing.get_origin(annotation) is not tuple:
        return None
    args = typing.get_args(annotation)
    if Ellipsis in args:      # a list of any length (events), not a vector
        return None
    inner = _shape(args[0])
    if inner is None:
        return f"a list of {len(args)} numbers"
    m = int(inner.split()[3])
    return f"a {len(args)}×{m} matrix, a list of {len(args)} lists of {m} numbers"


def _field_shape(keys: tuple) -> str | None:
    model = _model_at(keys)
    if model is None or keys[-1] not in model.model_fields:
        return None
    return _shape(model.model_fields[keys[-1]].annotation)


def _bool_words(text: str) -> str:
    # pydantic prints Python's True and False; YAML writes true and false.
    return re.sub(r"\bTrue\b", "true", re.sub(r"\bFalse\b", "false", text))


# What a value must be, by pydantic error type, in the scenario's own terms.
EXPECTED = {
    "float_type": "must be a number", "float_parsing": "must be a number",
    "int_type": "must be a whole number", "int_from_float": "must be a whole number",
    "int_parsing": "must be a whole number", "bool_type": "must be true or false",
    "bool_parsing": "must be true or false",
    "string_type": "must be text (quote it if it looks like a number)",
    "dict_type": "must be a mapping of keys, each key: value",
    "model_type": "must be a section, a mapping of keys, each key: value",
    "model_attributes_type": "must be a mapping of keys, each key: value",
    "list_type": "must be a list", "tuple_type": "must be a list",
    "finite_number": "must be a finite number (not .nan or .inf)",
    "string_too_short": "must not be empty",
}
_BOUNDS = {"greater_than": ("gt", "must be greater than {}"),
           "greater_than_equal": ("ge", "must be at least {}"),
           "less_than": ("lt", "must be less than {}"),
           "less_than_equal": ("le", "must be at most {}")}


def _message(error: dict, keys: tuple, in_union: bool) -> tuple[str, bool]:
    """What is wrong, in the field's terms, and whether to echo the value."""
    kind, ctx = error["type"], error.get("ctx") or {}
    if kind == "extra_forbidden":
        model = _model_at(error["loc"])
        return "unknown key" + (did_you_mean(str(keys[-1]), model.model_fields)
                                if model is not None else ""), False
    if kind == "missing" and not isinstance(error["loc"][-1], int):
        return "required key is missing", False
    if kind.startswith("union_tag"):
        return ("distribution must be 'normal' or 'uniform'" if kind == "union_tag_invalid"
                else "needs a distribution: normal or uniform"), True
    if in_union and kind in ("float_type", "tuple_type", "missing", "too_short",
                             "too_long"):
        # A dispersion parameter: a number, or a vector or matrix of the key's shape.
        return "must be a number, or a list of 3 numbers or a 3×3 matrix as the dispersed " \
               "key", True
    shape = _field_shape(keys) if keys else None
    if shape is not None and kind != "value_error":
        finite = " finite" if kind == "finite_number" else ""
        return f"must be {shape.replace(' numbers', finite + ' numbers')}", True
    if kind in _BOUNDS:
        name, text = _BOUNDS[kind]
        bound = ctx.get(name)
        return text.format(f"{bound:g}" if isinstance(bound, int | float) else bound), True
    if kind in ("literal_error", "enum"):
        return f"must be {_bool_words(str(ctx.get('expected', '')))}", True
    if kind in ("too_short", "too_long"):
        n = ctx.get("min_length" if kind == "too_short" else "max_length")
        return f"must have {'at least' if kind == 'too_short' else 'at most'} {n} " \
               f"item{'s' if n != 1 else ''}", True
    if kind in EXPECTED:
        return EXPECTED[kind], True
    msg = error["msg"].removeprefix("Value error, ").replace("Input should be", "must be")
    return _bool_words(msg), True


def problem_lines(exc: ValidationError, raw: dict | None = None,
                  sources: Sources | None = None) -> list[str]:
    """One line per problem key, each starting with its key path and saying what the
    value must be in the scenario's terms (a list of 3 numbers, a whole number, ...),
    then the value given and where it came from (``sources``: the file and line, or
    the ``--set``).  An unknown key names the closest valid key at the same place.  A
    vector or matrix with several bad elements is one problem."""
    lines: dict[str, list[str]] = {}
    tails: dict[str, str] = {}
    for error in exc.errors():
        # Union labels in a dispersion's loc ("...normal.sigma.float") are not keys
        # the user wrote; a union gives one error per alternative, keep the first.
        in_union = any(_union_label(p) and p not in DISTRIBUTION_TAGS for p in error["loc"])
        loc = tuple(p for p in error["loc"] if not _union_label(p))
        # The key path runs to the last key; indices after it are a value's elements
        # (a vector's [1]), those before it entries of a list of sections (events[3]).
        last_key = max((i for i, p in enumerate(loc) if not isinstance(p, int)), default=-1)
        first_int = next((i for i, p in enumerate(loc) if isinstance(p, int)
                          and i > last_key), len(loc))
        keys = loc[:first_int]
        where = key_path(keys)
        index = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in loc[first_int:])
        msg, echo = _message(error, keys, in_union)
        if not where:
            # Whole-scenario checks (the Monte Carlo keys) name their key paths
            # themselves, one line each.
            for line in msg.splitlines():
                lines.setdefault(line if ": " in line else f"scenario: {line}", [])
            continue
        if index and "list of" not in msg:   # not a message on the whole vector's shape
            msg = f"{msg} at {index}"
        if msg not in lines.setdefault(where, []):
            lines[where].append(msg)
        tails.setdefault(where, _tail(keys, echo, raw, error, sources))
    out = []
    for where, msgs in lines.items():
        if not msgs:
            out.append(where)
            continue
        more = len(msgs) - 1
        out.append(f"{where}: {msgs[0]}" + (f" (and {more} more in this value)" if more else "")
                   + tails[where])
    return out


def key_path(keys: tuple) -> str:
    """A key path as messages name it: ``sensors.earth.noise_deg``, ``events[3].kind``."""
    return "".join(f"[{k}]" if isinstance(k, int) else f".{k}" for k in keys).lstrip(".")


def _tail(keys: tuple, echo: bool, raw, error: dict, sources: Sources | None) -> str:
    """", got VALUE (FILE:LINE)": the value as given and where it came from (a
    ``--set`` of this very key shows the value itself)."""
    source = sources.of(keys) if sources is not None else None
    value = _value_at(raw, keys) if raw is not None else _ABSENT
    if value is _ABSENT and "input" in error and not isinstance(error["loc"][-1], int):
        value = error["input"]
    if error["type"] == "union_tag_invalid":
        value = (error.get("ctx") or {}).get("tag", value)
    exact_set = source is not None and source.startswith(
        f"--set {'.'.join(map(str, keys))}=")
    # An option of its own (--duration-s 600) shows the value as given, as --set does.
    own_option = source is not None and source.startswith("--") and not source.startswith(
        "--set ")
    got = f", got {shown(value)}" if (echo and value is not _ABSENT and not exact_set
                                      and not own_option) else ""
    return got + (f" ({source})" if source else "")


def format_error(exc: ValidationError, raw: dict | None = None,
                 sources: Sources | None = None) -> str:
    """Every problem, one line each (at most MAX_PROBLEM_LINES)."""
    return "\n".join(cap_lines(problem_lines(exc, raw, sources)))


def validate(raw: dict, sources: Sources | None = None) -> Scenario:
    try:
        return Scenario.model_validate(raw)
    except ValidationError as exc:
        raise ScenarioError(format_error(exc, raw, sources)) from None


def load_scenario(source: str | Path, overrides: list[str | tuple[str, str]] = ()
                  ) -> Scenario:
    """The validated scenario with ``key.path=value`` overrides applied in order.
    Every problem of the file and of the overrides is reported together, each with
    the value given and the file line or ``--set`` it came from.  An override may be
    ``(key.path=value, origin)``: the option it came from (``--duration-s 600``),
    named in its messages instead of ``--set``."""
    raw, path, text = _read_source(source)
    problems: list[str] = []
    applied = []
    for item in overrides:
        assignment, origin = item if isinstance(item, tuple) else (item, None)
        try:
            apply_override(raw, assignment, origin)
            applied.append((tuple(assignment.split("=", 1)[0].strip().split(".")),
                            origin or f"--set {assignment}"))
        except ScenarioError as exc:
            problems += exc.problems
    try:
        scenario = validate(raw, Sources(path, key_lines(text), tuple(applied)))
    except ScenarioError as exc:
        problems += exc.problems
    if problems:
        raise ScenarioError("\n".join(cap_lines(problems)))
    return scenario
