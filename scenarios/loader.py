"""Load, override and validate scenarios; write them back fully resolved.

Every failure is a ``ScenarioError`` with one line that names the key path (or
the file) and the problem, which the CLI prints before exiting with status 2.
"""

from __future__ import annotations

import re
from importlib import resources
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from . import __version__
from .montecarlo.schema import DISTRIBUTION_TAGS
from .schema import Scenario


class ScenarioError(ValueError):
    """A bad scenario: the message is one line naming the key path."""


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
    return Path(str(resources.files("scenarios")))


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


def format_error(exc: ValidationError) -> str:
    """One line: the first problem's key path and message (+ how many more)."""
    errors = exc.errors()
    first = errors[0]
    # Union labels in a dispersion's loc ("...normal.sigma.float") are not keys the
    # user wrote.
    loc = ".".join(str(p) for p in first["loc"] if not _union_label(p))
    msg = first["msg"].removeprefix("Value error, ")
    if not loc:
        # Whole-scenario checks (the Monte Carlo keys) name their key path themselves.
        loc, _, msg = msg.partition(": ") if ": " in msg else ("scenario", "", msg)
    if first["type"] == "extra_forbidden":
        msg = "unknown key"
    elif first["type"] == "missing":
        msg = "missing value (wrong length)" if isinstance(first["loc"][-1], int) \
            else "required key is missing"
    more = f" (and {len(errors) - 1} more problem{'s' * (len(errors) > 2)})" \
        if len(errors) > 1 else ""
    return f"{loc}: {msg}{more}"


def validate(raw: dict) -> Scenario:
    try:
        return Scenario.model_validate(raw)
    except ValidationError as exc:
        raise ScenarioError(format_error(exc)) from None


def load_scenario(source: str | Path, overrides: list[str] = ()) -> Scenario:
    raw, _ = read_raw(source)
    for assignment in overrides:
        apply_override(raw, assignment)
    return validate(raw)


def resolved_yaml(scenario: Scenario) -> str:
    """Every key with its value, defaults filled, stamped with this version; loads
    back to the same scenario."""
    data = scenario.model_dump(mode="json")
    data["dynprop_version"] = __version__
    return yaml.safe_dump(data, sort_keys=False, allow_unicode=True, width=100)
