"""Typed configuration: a tree of dataclasses, each field documented, loaded strictly.

YAML files chain with ``inherit_from`` (mappings merge, anything else replaces), then
``key.sub=value`` overrides apply. An unknown key, a wrong type or an invalid value is a
:class:`ConfigError` naming the file (or "command line"), the dotted key and the closest
valid key. The machinery works on any dataclass tree: a new section is a new dataclass.
A ``__post_init__`` check raises ValueError starting with the field's name ("threads
must be >= 0, ...") so the error can name the file that set that field.

Over 400 lines on purpose: one reader of the config language (files, inheritance,
overrides, type coercion, the errors naming the file and key), whose parts share the
type walk over the dataclass tree.
"""

from __future__ import annotations

import ast
import contextlib
import dataclasses
import difflib
import functools
import inspect
import itertools
import json
import os
import re
import textwrap
import types
import typing
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Literal, NamedTuple, TypeVar, Union

import yaml

from eslam.atomic import write_text
from eslam.config.packaged import find_config
from eslam.config.schema import MOVED_KEYS, ESLAMConfig
from eslam.errors import ConfigError

T = TypeVar("T")
Origins = dict[tuple[str, ...], str]
"""Where each key came from: dotted path parts -> file name or "command line"."""

COMMAND_LINE = "command line"
_UNIONS = (Union, types.UnionType)


class FieldHelp(NamedTuple):
    """One leaf setting, as ``config_help`` lists it."""

    key: str
    type: str
    default: str
    doc: str


def _section_of(tp: Any) -> type | None:
    """The dataclass of a section field typed ``Section`` or ``Section | None``, else None."""
    if typing.get_origin(tp) in _UNIONS:
        kinds = [a for a in typing.get_args(tp) if a is not type(None)]
        tp = kinds[0] if len(kinds) == 1 else None
    return tp if isinstance(tp, type) and dataclasses.is_dataclass(tp) else None


@functools.cache
def _fields(cls: type) -> dict[str, tuple[dataclasses.Field, Any]]:
    """The settable fields of a dataclass: name -> (field, resolved type)."""
    hints = typing.get_type_hints(cls)
    return {f.name: (f, hints[f.name]) for f in dataclasses.fields(cls) if f.init}


@functools.cache
def field_docs(cls: type) -> Mapping[str, str]:
    """The docstrings placed directly under the fields of ``cls`` (and of its bases).

    Dataclasses drop these string literals, so they are read back from the source.
    """
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if not dataclasses.is_dataclass(klass):
            continue
        try:
            tree = ast.parse(textwrap.dedent(inspect.getsource(klass)))
        except (OSError, TypeError):
            continue
        body = tree.body[0].body if isinstance(tree.body[0], ast.ClassDef) else []
        for node, after in itertools.pairwise(body):
            if (
                isinstance(node, ast.AnnAssign)
                and isinstance(node.target, ast.Name)
                and isinstance(after, ast.Expr)
                and isinstance(after.value, ast.Constant)
                and isinstance(after.value.value, str)
            ):
                docs[node.target.id] = inspect.cleandoc(after.value.value)
    return types.MappingProxyType(docs)


def _type_name(tp: Any) -> str:
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is type(None):
        return "null"
    if origin in _UNIONS:
        return " | ".join(_type_name(a) for a in args)
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in args)
    if origin is not None:
        inner = ", ".join("..." if a is Ellipsis else _type_name(a) for a in args)
        return f"{origin.__name__}[{inner}]"
    return getattr(tp, "__name__", str(tp))


def _default_of(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return dataclasses.MISSING


def config_help(schema: type = ESLAMConfig, prefix: str = "") -> list[FieldHelp]:
    """List every leaf setting of ``schema``: dotted key, type, default (JSON), docstring."""
    rows: list[FieldHelp] = []
    docs = field_docs(schema)
    for name, (f, tp) in _fields(schema).items():
        key = prefix + name
        section = _section_of(tp)
        if section is not None:
            rows += config_help(section, key + ".")
            continue
        default = _default_of(f)
        shown = "(required)" if default is dataclasses.MISSING else json.dumps(_plain(default))
        rows.append(FieldHelp(key, _type_name(tp), shown, docs.get(name, "")))
    return rows


def _origin(origins: Origins, path: tuple[str, ...], default: str) -> str:
    for end in range(len(path), 0, -1):
        if path[:end] in origins:
            return origins[path[:end]]
    return default


def _suggest(key: str, valid: Sequence[str], prefix: str) -> str:
    moved = MOVED_KEYS.get(f"{prefix}{key}")
    if moved is not None:
        return f"it moved: use '{moved}'"
    match = difflib.get_close_matches(key, valid, n=1)
    if match:
        return f"did you mean '{prefix}{match[0]}'?"
    where = f"under '{prefix[:-1]}'" if prefix else "at the top level"
    return f"valid keys {where}: {', '.join(valid)}"


def _coerce(value: Any, tp: Any, key: str, source: str) -> Any:
    """Check ``value`` against the type ``tp`` and convert it (int -> float, list -> tuple)."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)

    def fail(extra: str = "") -> ConfigError:
        return ConfigError(f"{source}: '{key}' expects {_type_name(tp)}, got {given!r}{extra}")

    given = value
    if origin in _UNIONS:
        kinds = [a for a in args if a is not type(None)]
        if value is None and len(kinds) < len(args):
            return None
        if len(kinds) == 1:  # Optional: the inner type's error is the precise one
            return _coerce(value, kinds[0], key, source)
        for kind in kinds:
            with contextlib.suppress(ConfigError):
                return _coerce(value, kind, key, source)
        raise fail()
    if origin is Literal:
        if any(value == a and type(value) is type(a) for a in args):
            return value
        close = difflib.get_close_matches(str(value), [str(a) for a in args], n=1)
        raise fail(f" (did you mean '{close[0]}'?)" if close else "")
    if tp is bool and isinstance(value, bool):
        return value
    if tp in (int, float) and isinstance(value, str):
        try:  # PyYAML reads 1e-3 (no dot) as text
            value = float(value)
        except ValueError:
            raise fail() from None
    if tp is int and not isinstance(value, bool):
        if isinstance(value, int) or (isinstance(value, float) and value.is_integer()):
            return int(value)
        raise fail()
    if tp is float and isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value)
    if tp is str and isinstance(value, str):
        return value
    if origin in (list, tuple) and isinstance(value, (list, tuple)):
        if origin is list or (len(args) == 2 and args[1] is Ellipsis):
            items = [_coerce(v, args[0], f"{key}[{i}]", source) for i, v in enumerate(value)]
            return items if origin is list else tuple(items)
        if len(value) != len(args):
            raise fail(f" ({len(args)} items needed)")
        return tuple(
            _coerce(v, a, f"{key}[{i}]", source)
            for i, (v, a) in enumerate(zip(value, args, strict=True))
        )
    if origin is None and tp not in (bool, int, float, str) and isinstance(value, tp):
        return value
    raise fail()


def _build(
    schema: type[T], data: Mapping, origins: Origins, path: tuple[str, ...], source: str
) -> T:
    prefix = "".join(p + "." for p in path)
    fields = _fields(schema)
    for key in data:
        if key not in fields:
            where = _origin(origins, (*path, key), source)
            hint = _suggest(str(key), list(fields), prefix)
            raise ConfigError(f"{where}: unknown key '{prefix}{key}' ({hint})")
    values: dict[str, Any] = {}
    for name, (f, tp) in fields.items():
        where = _origin(origins, (*path, name), source)
        if name not in data:
            if _default_of(f) is dataclasses.MISSING:
                raise ConfigError(f"{where}: missing required key '{prefix}{name}'")
            continue
        value = data[name]
        section = _section_of(tp)
        if section is not None and value is None and section is not tp:
            values[name] = None  # an optional section switched off
        elif section is not None:
            if value is None:  # a section whose keys are all commented out
                value = {}
            if not isinstance(value, Mapping):
                raise ConfigError(
                    f"{where}: '{prefix}{name}' is a section and expects a mapping of "
                    f"its keys, got {value!r}"
                )
            values[name] = _build(section, value, origins, (*path, name), source)
        else:
            values[name] = _coerce(value, tp, prefix + name, where)
    try:
        return schema(**values)
    except ValueError as error:  # from __post_init__; it names the field first, if it can
        where = _blame(schema, values, data, origins, (path, source), str(error))
        if any(str(error).startswith(f"{name} ") for name in data):
            raise ConfigError(f"{where}: {prefix}{error}") from None
        what = f"section '{prefix[:-1]}'" if path else "config"
        raise ConfigError(f"{where}: invalid {what}: {error}") from None


def _blame(
    schema: type,
    values: dict[str, Any],
    data: Mapping,
    origins: Origins,
    at: tuple[tuple[str, ...], str],
    message: str,
) -> str:
    """Where the value a section's check rejected (``message``) came from.

    A check may name several keys ("every must be >= 1, window >= 3"): the culprits are
    the named keys whose value, put back to its default, lets the section pass. Their
    origin is blamed, the command line first (a value typed there, never the file that
    set a sibling); without culprits, the origins of every named key (of all the
    section's keys when it names none). ``at`` is (section path, default origin).
    """
    path, source = at
    named = [n for n in data if re.search(rf"\b{re.escape(str(n))}\b", message)] or list(data)
    culprits = [n for n in named if _passes_without(schema, values, n)]
    found = [o for n in culprits or named for o in _origins_within(origins, (*path, n), source)]
    if culprits and COMMAND_LINE in found:
        return COMMAND_LINE
    return ", ".join(dict.fromkeys(found)) or source


def _passes_without(schema: type, values: dict[str, Any], name: str) -> bool:
    """Whether ``schema`` accepts ``values`` with ``name`` left at its default."""
    try:
        schema(**{k: v for k, v in values.items() if k != name})
    except (ValueError, TypeError):
        return False
    return True


def _origins_within(origins: Origins, at: tuple[str, ...], default: str) -> list[str]:
    """Where the key ``at`` and everything under it came from (a section's keys may come
    from several files and the command line)."""
    inside = [origin for key, origin in origins.items() if key[: len(at)] == at]
    return inside or [_origin(origins, at, default)]


def config_from_dict(
    data: Mapping | None, schema: type[T] = ESLAMConfig, source: str = "<dict>"
) -> T:
    """Build the dataclass tree ``schema`` from plain data, strictly.

    Args:
        data: nested mappings of plain values (as ``yaml.safe_load`` returns); missing
            keys keep their defaults. ``None`` means all defaults.
        schema: the root dataclass.
        source: what to name as the origin of the data in error messages.

    Raises:
        ConfigError: an unknown key, a value of the wrong type or an invalid value.
    """
    if data is not None and not isinstance(data, Mapping):
        raise ConfigError(f"{source}: expected a mapping of keys at the top level, got {data!r}")
    return _build(schema, data or {}, {}, (), source)


def _read_yaml(path: Path, name: str) -> dict:
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as error:
        raise ConfigError(f"{name}: cannot read config file ({error.strerror})") from None
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(error, "problem", None) or str(error).splitlines()[0]
        raise ConfigError(f"{name}: invalid YAML{where}: {problem}") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(f"{name}: expected a mapping of keys at the top level, got {data!r}")
    return data


def _merge(base: dict, origins: Origins, child: Mapping, source: str, path: tuple = ()) -> None:
    """Deep-merge ``child`` into ``base`` in place, recording where each key came from."""
    for key, value in child.items():
        at = (*path, key)
        if isinstance(base.get(key), dict) and isinstance(value, Mapping):
            _merge(base[key], origins, value, source, at)
            continue
        for stale in [p for p in origins if p[: len(at)] == at]:
            del origins[stale]
        base[key] = value
        origins[at] = source


def _load_chain(path: Path, name: str, chain: tuple[Path, ...] = ()) -> list[tuple[str, dict]]:
    """The layers (file name, data) of ``path`` and its ancestors, in merge order."""
    real = path.resolve()
    if real in chain:
        names = " -> ".join([*(p.name for p in chain), path.name])
        raise ConfigError(f"{name}: inheritance cycle: {names}")
    data = _read_yaml(path, name)
    parents = data.pop("inherit_from", None)
    if isinstance(parents, str):
        parents = [parents]
    if parents is not None and (
        not isinstance(parents, list) or not all(isinstance(p, str) for p in parents)
    ):
        raise ConfigError(
            f"{name}: inherit_from must be a path or a list of paths, got {parents!r}"
        )
    layers: list[tuple[str, dict]] = []
    for parent in parents or []:
        parent_name = os.path.normpath(os.path.join(os.path.dirname(name), parent))
        parent_path = path.parent / parent
        if not parent_path.is_file():
            raise ConfigError(
                f"{name}: inherit_from '{parent}' not found (looked for {parent_name})"
            )
        layers += _load_chain(parent_path, parent_name, (*chain, real))
    return [*layers, (name, data)]


def _takes_text(tp: Any) -> bool:
    """Whether every non-null form of ``tp`` is text (so `key=2024` stays '2024')."""
    kinds = typing.get_args(tp) if typing.get_origin(tp) in _UNIONS else (tp,)
    text = [a is str or {type(c) for c in typing.get_args(a)} == {str} for a in kinds]
    return any(text) and all(t or a is type(None) for t, a in zip(text, kinds, strict=True))


def _apply_override(text: str, schema: type, data: dict, origins: Origins) -> None:
    key, equals, raw = text.partition("=")
    key = key.strip()
    if not equals or not key:
        raise ConfigError(f"{COMMAND_LINE}: '{text}' is not key=value (e.g. seed=1)")
    parts = tuple(key.split("."))
    tp: Any = schema
    for i, part in enumerate(parts):
        section = _section_of(tp)
        if section is None:
            parent = ".".join(parts[:i])
            raise ConfigError(f"{COMMAND_LINE}: cannot set '{key}': '{parent}' is not a section")
        fields = _fields(section)
        if part not in fields:
            prefix = "".join(p + "." for p in parts[:i])
            hint = _suggest(part, list(fields), prefix)
            raise ConfigError(f"{COMMAND_LINE}: unknown key '{prefix}{part}' ({hint})")
        tp = fields[part][1]
    section = _section_of(tp)
    if section is not None:
        example = f"{key}.{next(iter(_fields(section)), 'key')}=..."
        raise ConfigError(f"{COMMAND_LINE}: '{key}' is a section; set its keys (e.g. {example})")
    try:
        value = yaml.safe_load(raw)
    except yaml.YAMLError:
        raise ConfigError(f"{COMMAND_LINE}: cannot parse the value of '{key}': {raw!r}") from None
    if value is not None and not isinstance(value, str) and _takes_text(tp):
        value = raw.strip()
    nested: Any = value
    for part in reversed(parts):
        nested = {part: nested}
    _merge(data, origins, nested, COMMAND_LINE)


def load_config(
    path: str | Path | None, overrides: Sequence[str] = (), schema: type[T] = ESLAMConfig
) -> T:
    """Load a YAML config (following ``inherit_from``), apply overrides, check everything.

    Args:
        path: the YAML file, or the name of a packaged config (``replica/room0``,
            :func:`eslam.config.packaged.find_config`; an existing path wins); ``None``
            starts from the schema's defaults.
        overrides: ``key.sub=value`` strings, applied in order after the files; each
            value is read as YAML (``1e-3``, ``[1, 2]``, ``null``) and then checked
            against the field's type. Text fields keep the raw text (``data.path=2024``).
        schema: the root dataclass.

    Returns:
        The fully resolved config.

    Raises:
        ConfigError: a missing or unreadable file, an inheritance cycle, an unknown key,
            a wrong type or an invalid value; the message names the file (or "command
            line"), the dotted key and the closest valid key.
    """
    data: dict = {}
    origins: Origins = {}
    source = "defaults"
    if path is not None:
        path = find_config(path)  # a path that exists, else a packaged config's name
        source = str(path)
        for name, layer in _load_chain(path, source):
            _merge(data, origins, layer, name)
    for text in overrides:
        _apply_override(text, schema, data, origins)
    return _build(schema, data, origins, (), source)


def _plain(value: Any) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {name: _plain(getattr(value, name)) for name in _fields(type(value))}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    return value


def config_to_dict(cfg: Any) -> dict[str, Any]:
    """The config as plain nested dicts, lists and scalars, fields in declaration order."""
    if not dataclasses.is_dataclass(cfg) or isinstance(cfg, type):
        raise TypeError(f"expected a config dataclass instance, got {type(cfg).__name__}")
    return _plain(cfg)


class _Dumper(yaml.SafeDumper):
    """Safe YAML with lists of scalars on one line (bound: [[0.0, 1.0], ...])."""


_Dumper.add_representer(
    list,
    lambda dumper, data: dumper.represent_sequence(
        "tag:yaml.org,2002:seq", data, flow_style=not any(isinstance(v, dict) for v in data)
    ),
)


def save_config(cfg: Any, path: str | Path) -> None:
    """Write the fully resolved ``cfg`` to ``path`` as plain YAML, atomically.

    ``load_config(path)`` gives back an equal config.
    """
    body = yaml.dump(config_to_dict(cfg), Dumper=_Dumper, sort_keys=False, allow_unicode=True)
    write_text(path, "# Fully resolved eslam config (eslam.config.load_config reads it).\n" + body)
