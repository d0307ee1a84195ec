"""What a study is read from: its file, the files it extends, and changes from the command line.

A family of studies that differ in a few settings is a base and variants (issue 48)::

    # study_ray.toml: the base's every section, with these changes
    [study]
    extends = "study_cpp.toml"     # relative to this file
    name = "measures_ray"

    [measure]
    name = "ray"

A file that only holds what a family shares, and is no study by itself, says so with
``[study] base_only = true``: its variants extend it, ``fbia run`` refuses it, and the
setting is not passed on to them.

The variant's tables are merged into the base's key by key (a table in both is merged the same
way, any other value of the variant replaces the base's: an array such as ``[[parameters]]`` is
replaced whole); a base may extend another (at most :data:`MAX_DEPTH` files), a cycle is
refused. Relative paths in the merged study, the base's included, are read from the folder of
the file that is run (the extending one), as if it said them itself.

``fbia run/validate/forward --set section.key=value`` changes one value after the merge: the
key is a dotted path through tables (an array of tables takes an index, ``parameters.0.bounds``),
the value a TOML value (``3``, ``[100.0, 900.0]``, ``"cpp"``; a bare word is a string).

The result records every source (:class:`StudySources`): the file's own text, the bases' texts
and the changes, and one SHA-256 over them (the file's own when it has neither), so a result
can be remade from its record.
"""

from __future__ import annotations

import hashlib
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..core.errors import ConfigError

#: the most files one study may be read from (itself and the bases it extends, in a chain)
MAX_DEPTH = 8


@dataclass(frozen=True)
class StudySource:
    """One file a study is read from: its path as named and its text."""

    path: str
    text: str


@dataclass(frozen=True)
class StudySources:
    """Everything a study was read from: the merged table, the file's own text and bytes'
    SHA-256 digest, the bases it extends (nearest first) and the ``--set`` changes."""

    raw: dict[str, Any]
    text: str
    sha256: str
    bases: tuple[StudySource, ...] = ()
    overrides: tuple[str, ...] = ()


def read_toml(path: Path) -> tuple[dict[str, Any], str, bytes]:
    """The table, text and bytes of the TOML file ``path`` (a one-line ConfigError naming the
    file for anything that is not a readable UTF-8 TOML file)."""
    file = str(path)
    if not path.is_file():
        raise ConfigError("study file not found" if not path.exists() else "not a file", file)
    raw_bytes = path.read_bytes()
    try:
        text = raw_bytes.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"not UTF-8 text ({exc.reason} at byte {exc.start})", file) from None
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"TOML syntax error: {exc}", file) from None
    except RecursionError:  # tomllib recurses once per level of nesting
        message = "TOML nested too deeply (arrays or tables in one another)"
        raise ConfigError(message, file) from None
    return raw, text, raw_bytes


def read_sources(path: Path, overrides: Sequence[str] = ()) -> StudySources:
    """The study file ``path`` with the bases it extends merged in and ``overrides``
    (``section.key=value``) applied (module docstring)."""
    raw, text, raw_bytes = read_toml(path)
    merged, bases = raw, list[StudySource]()
    chain, here, current = [path.resolve()], path, raw
    while (named := _extends(current, here)) is not None:
        base = here.parent / named
        where = f"{here}: [study] extends"
        if base.resolve() in chain:
            loop = " -> ".join(str(p) for p in [*chain, base.resolve()])
            raise ConfigError(f"the studies extend each other in a cycle: {loop}", where)
        if len(chain) >= MAX_DEPTH:
            raise ConfigError(f"more than {MAX_DEPTH} files extend one another", where)
        try:
            current, base_text, _ = read_toml(base)
        except ConfigError as err:
            raise ConfigError(f"{named!r}: {err}", where) from None
        bases.append(StudySource(str(base), base_text))
        merged = merge_tables(current, merged)
        chain.append(base.resolve())
        here = base
    if bases:
        # what a file says of itself is not inherited: whom it extends, whether it is a base
        study = dict(merged["study"])
        study.pop("extends")
        study.pop("base_only", None)
        own = raw["study"].get("base_only")
        if own is not None:
            study["base_only"] = own
        merged = {**merged, "study": study}
    for change in overrides:
        merged = with_override(merged, change)
    sha = hashlib.sha256(raw_bytes)
    for source in bases:
        sha.update(b"\0" + source.text.encode("utf-8"))
    for change in overrides:
        sha.update(b"\0--set " + change.encode("utf-8"))
    digest = sha.hexdigest()
    return StudySources(merged, text, digest, tuple(bases), tuple(overrides))


def merge_tables(base: Mapping[str, Any], variant: Mapping[str, Any]) -> dict[str, Any]:
    """``base`` with ``variant``'s keys: tables in both merged the same way, any other value of
    the variant in place of the base's (a new table; neither is changed)."""
    out = dict(base)
    for key, value in variant.items():
        old = out.get(key)
        if isinstance(old, dict) and isinstance(value, dict):
            out[key] = merge_tables(old, value)
        else:
            out[key] = value
    return out


def with_override(raw: Mapping[str, Any], change: str) -> dict[str, Any]:
    """``raw`` with the value of one ``section.key=value`` change (module docstring); a new
    table, ``raw`` is not changed."""
    where = f"--set {change}"
    key, sep, text = change.partition("=")
    parts = key.strip().split(".")
    if not sep or len(parts) < 2 or not all(parts):
        raise ConfigError("expected section.key=value, e.g. iterator.options.seed=3", where)
    value = _value(text.strip(), where)
    return _set(dict(raw), parts, value, where)


def _extends(raw: Mapping[str, Any], path: Path) -> str | None:
    study = raw.get("study")
    named = study.get("extends") if isinstance(study, dict) else None
    if named is None:
        return None
    if not isinstance(named, str) or not named.strip():
        where = f"{path}: [study] extends"
        raise ConfigError("expected the path of a study file (a string)", where)
    return named


def _value(text: str, where: str) -> Any:
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        if text and not any(c in text for c in "\"'[]{}=,#\n"):
            return text  # a bare word: a string
        raise ConfigError(f"not a TOML value: {text!r}", where) from None


def _set(node: Any, parts: Sequence[str], value: Any, where: str, path: str = "") -> Any:
    """``node`` (a table or an array of tables, named ``path``) with ``value`` at the dotted
    ``parts`` below it; a new one, ``node`` is not changed."""
    head, rest = parts[0], parts[1:]
    name = f"{path}.{head}" if path else head
    if isinstance(node, list):
        if not head.isdigit() or int(head) >= len(node):
            raise ConfigError(
                f"{path} is an array of {len(node)}: give an index 0..{len(node) - 1}", where
            )
        items = list(node)
        items[int(head)] = value if not rest else _set(items[int(head)], rest, value, where, name)
        return items
    if not isinstance(node, dict):
        raise ConfigError(f"{path} is a value, not a table", where)
    table = dict(node)
    table[head] = value if not rest else _set(table.get(head, {}), rest, value, where, name)
    return table
