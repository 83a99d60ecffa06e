"""One line per problem, and the valid name a misspelt one most likely meant: how
every bad input (a scenario key, a telemetry column, an argument) is reported."""

from __future__ import annotations

import difflib

MAX_PROBLEM_LINES = 10


def closest(word: str, candidates) -> str | None:
    """The valid name a misspelt ``word`` most likely meant, if any is close.

    difflib's ratio catches transpositions and small slips (``nmae`` → ``name``);
    a key written without its unit suffix (``inertia`` → ``inertia_kgm2``) is
    caught by its prefix even where the ratio is low."""
    candidates = [str(c) for c in candidates]
    match = difflib.get_close_matches(str(word), candidates, n=1, cutoff=0.6)
    if match:
        return match[0]
    prefixed = [c for c in candidates if c.startswith(f"{word}_")]
    return prefixed[0] if len(prefixed) == 1 else None


def did_you_mean(word: str, candidates) -> str:
    match = closest(word, candidates)
    return f"; did you mean '{match}'?" if match else ""


def cap_lines(lines: list[str], limit: int = MAX_PROBLEM_LINES) -> list[str]:
    """At most ``limit`` lines; the last says how many more were found."""
    if len(lines) <= limit:
        return lines
    more = len(lines) - (limit - 1)
    return lines[:limit - 1] + [f"... and {more} more problems"]


def shown(value, limit: int = 60) -> str:
    """A value as the user wrote it in YAML (flow style: ``[1, 2]``, ``.nan``, ``true``),
    cut to ``limit`` characters."""
    import yaml
    try:
        text = yaml.safe_dump(value, default_flow_style=True, width=10**6,
                              allow_unicode=True).strip()
    except yaml.YAMLError:
        text = repr(value)
    text = text.removesuffix("...").strip()
    return text if len(text) <= limit else text[:limit - 1] + "…"
