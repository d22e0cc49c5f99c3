"""``key=value`` overrides onto a typed, frozen config (train, rollout and benchmarks share it).

Nested dataclass fields are addressed with dots (``env.solver_iterations=8``). Values
are parsed by the field's annotated type: integers also as whole floats (``2e6``), tuples
as comma-separated items (``network.mlp_hidden=64,64``, or ``(64,64)``). An unknown key
or a bad value is one error line naming it, with the closest valid keys.
"""

import ast
import dataclasses
import difflib
import inspect
import math
import textwrap
import types
import typing
from collections.abc import Sequence

from solar_jax.config import METHOD_KEYS, SCHEDULES, ConfigError, TrainConfig
from solar_jax.morphology.variants import Variation, VariationError
from solar_jax.training.rundir import check_resumable, saved_config

HELP_FLAGS = ("-h", "--help", "help")


def _fields(cls) -> dict[str, dataclasses.Field]:
    return {f.name: f for f in dataclasses.fields(cls)}


def valid_keys(cls, prefix: str = "") -> list[str]:
    """Every settable dotted key of a config dataclass."""
    keys = []
    hints = typing.get_type_hints(cls)
    for name in _fields(cls):
        kind = hints[name]
        if dataclasses.is_dataclass(kind):
            keys += valid_keys(kind, f"{prefix}{name}.")
        else:
            keys.append(prefix + name)
    return keys


def _parse(key: str, text: str, kind):
    origin = typing.get_origin(kind)
    if origin in (typing.Union, types.UnionType):
        options = [k for k in typing.get_args(kind) if k is not type(None)]
        if text.lower() in ("none", "null") and len(options) < len(typing.get_args(kind)):
            return None
        return _parse(key, text, options[0])
    if kind is bool:
        if text.lower() in ("1", "true", "yes", "on"):
            return True
        if text.lower() in ("0", "false", "no", "off"):
            return False
        raise ConfigError(f"{key}={text}: expected a boolean (true/false)")
    if kind is float:
        try:
            return float(text)
        except ValueError:
            raise ConfigError(f"{key}={text}: expected float") from None
    if kind is int:
        try:
            return int(text)
        except ValueError:
            pass
        try:  # 2e6: a float that is a whole number
            number = float(text)
        except ValueError:
            number = math.nan
        if not number.is_integer():
            raise ConfigError(f"{key}={text}: expected int") from None
        return int(number)
    if kind is str:
        return text
    if origin is tuple:
        items = typing.get_args(kind)
        if len(items) != 2 or items[1] is not Ellipsis:
            raise ConfigError(f"{key}: cannot be set from the command line")
        parts = text.strip().removeprefix("(").removesuffix(")").split(",")
        parts = [p.strip() for p in parts if p.strip()]
        if not parts:
            raise ConfigError(f"{key}={text}: expected comma-separated items, e.g. 64,64")
        return tuple(_parse(key, p, items[0]) for p in parts)
    if typing.get_origin(kind) is typing.Literal:
        choices = typing.get_args(kind)
        if text not in choices:
            raise ConfigError(f"{key}={text}: expected one of {', '.join(map(str, choices))}")
        return text
    raise ConfigError(f"{key}: cannot be set from the command line")


def apply_overrides(config, overrides: dict[str, str], prefix: str = ""):
    """A copy of ``config`` with the dotted ``overrides`` parsed and applied (``prefix``:
    where ``config`` sits in the outer one, for messages)."""
    grouped: dict[str, dict[str, str]] = {}
    changes = {}
    fields = _fields(type(config))
    hints = typing.get_type_hints(type(config))
    for key, text in overrides.items():
        head, _, rest = key.partition(".")
        if head not in fields or (rest and not dataclasses.is_dataclass(hints[head])):
            raise ConfigError(unknown_key(prefix + key, valid_keys(type(config), prefix)))
        if rest:
            grouped.setdefault(head, {})[rest] = text
        elif dataclasses.is_dataclass(hints[head]):
            full = prefix + key
            raise ConfigError(f"'{full}' is a group; set one of its fields, e.g. {full}.<field>")
        else:
            changes[head] = _parse(prefix + key, text, hints[head])
    for head, sub in grouped.items():
        changes[head] = apply_overrides(getattr(config, head), sub, f"{prefix}{head}.")
    try:
        return dataclasses.replace(config, **changes)
    except ValueError as err:  # a config's own validation (__post_init__)
        raise ConfigError(str(err)) from None


def unknown_key(key: str, valid: Sequence[str]) -> str:
    """The error line for ``key``: the closest of ``valid`` (up to three; a field name is
    also matched against the fields of every section, ``lr`` to ``td3.lr``), else a known
    section's fields."""
    section, _, field = key.rpartition(".")
    siblings = [k for k in valid if k.rpartition(".")[0] == section]
    pool = siblings if section and siblings else valid
    by_field: dict[str, list[str]] = {}
    for k in pool:
        by_field.setdefault(k.rpartition(".")[2], []).append(k)
    close = [
        k for f in difflib.get_close_matches(field, by_field, n=3, cutoff=0.6) for k in by_field[f]
    ]
    if close:
        return f"unknown config key '{key}'; did you mean {' or '.join(close[:3])}?"
    if section and siblings:
        return f"unknown config key '{key}'; {section}'s keys: {', '.join(siblings)}"
    if len(valid) <= 12:  # a command's few options: all of them
        return f"unknown config key '{key}'; keys: {', '.join(valid)}"
    return f"unknown config key '{key}' (--help lists the keys)"


def split_arguments(config_cls, argv: Sequence[str]) -> dict[str, str]:
    """``["a=1", "env.b=2"]`` -> ``{"a": "1", "env.b": "2"}`` (not yet parsed or checked)."""
    overrides = {}
    for arg in argv:
        key, sep, text = arg.partition("=")
        if not sep or not key:
            raise ConfigError(f"'{arg}': arguments are key=value (--help lists the keys)")
        overrides[key] = text
    return overrides


def parse_overrides(config, argv: Sequence[str]):
    """``["a=1", "env.b=2"]`` applied onto ``config``."""
    return apply_overrides(config, split_arguments(type(config), argv))


def parse_config(argv: list[str]) -> TrainConfig:
    """The config of a command line (``_parse_config``), its ``env.variation`` checked."""
    config = _parse_config(argv)
    if config.env.variation:
        try:
            Variation.parse(config.env.variation)
        except VariationError as err:
            raise ConfigError(f"env.variation: {err}") from None
    return config


def _parse_config(argv: list[str]) -> TrainConfig:
    """The config of a command line.

    ``net=tiny`` (or ``small``) starts from that network preset, ``schedule=fast`` applies
    that schedule's keys (``SCHEDULES``) on it, then the method's (``METHOD_KEYS``), and
    the command line's keys go on top.
    With ``resume=RUN_DIR`` the saved run's config is the base, and only the keys in
    ``RESUMABLE`` may be given besides.
    """
    overrides = split_arguments(TrainConfig, argv)
    if "resume" in overrides:
        run_dir = overrides.pop("resume")
        check_resumable(run_dir, overrides, "run")
        base = dataclasses.replace(saved_config(run_dir), resume=run_dir, out=run_dir)
        return apply_overrides(base, overrides)
    base = TrainConfig()
    if "net" in overrides:  # first: the preset, so that network.* keys go on top of it
        base = apply_overrides(base, {"net": overrides.pop("net")})
    if "schedule" in overrides:  # then its keys, the command line's on top
        schedule = overrides.pop("schedule")
        base = apply_overrides(base, {"schedule": schedule})
        base = apply_overrides(base, SCHEDULES[schedule])
    if "method" in overrides:  # then the method's own (METHOD_KEYS)
        method = overrides.pop("method")
        base = apply_overrides(base, {"method": method})
        base = apply_overrides(base, METHOD_KEYS.get(method, {}))
    return apply_overrides(base, overrides)


# --------------------------------------------------------------------------------- help
def wants_help(argv: Sequence[str]) -> tuple[bool, str | None]:
    """(asked for help?, the section asked for): ``--help`` or ``--help td3``."""
    if not argv or argv[0] not in HELP_FLAGS:
        return False, None
    return True, (argv[1] if len(argv) > 1 else None)


def field_docs(cls) -> dict[str, str]:
    """A dataclass's attribute docstrings (the string literal under a field), read from
    its source and its bases': ``{field: text}``."""
    docs = {}
    for klass in reversed([k for k in cls.__mro__ if dataclasses.is_dataclass(k)]):
        body = ast.parse(textwrap.dedent(inspect.getsource(klass))).body[0].body
        for node, after in zip(body, [*body[1:], None], strict=True):
            is_doc = (
                isinstance(after, ast.Expr)
                and isinstance(after.value, ast.Constant)
                and isinstance(after.value.value, str)
            )
            if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and is_doc:
                docs[node.target.id] = " ".join(inspect.cleandoc(after.value.value).split())
    return docs


def _type_name(kind) -> str:
    origin = typing.get_origin(kind)
    if origin is typing.Literal:
        return "|".join(map(str, typing.get_args(kind)))
    if origin in (typing.Union, types.UnionType):
        names = [_type_name(k) for k in typing.get_args(kind) if k is not type(None)]
        return " or ".join([*names, "none"])
    if origin is tuple:
        item = typing.get_args(kind)[0]
        if typing.get_origin(item) is typing.Literal:
            return f"comma-separated, of {_type_name(item)}"
        return f"comma-separated {_type_name(item)}s"
    return getattr(kind, "__name__", str(kind))


def plain(text: str) -> str:
    """Docstring text for a terminal: ``code`` without its reStructuredText quotes."""
    return text.replace("``", "")


def _entries(config, prefix: str = "") -> dict[str, list[tuple[str, str, str]]]:
    """{section: [(key=default, type, docstring)]}; the top level is section ""."""
    cls = type(config)
    docs, hints = field_docs(cls), typing.get_type_hints(cls)
    sections: dict[str, list] = {prefix.rstrip("."): []}
    for name in _fields(cls):
        value = getattr(config, name)
        if dataclasses.is_dataclass(hints[name]):
            sections |= _entries(value, f"{prefix}{name}.")
            continue
        shown = "none" if value is None else value
        shown = str(shown).lower() if isinstance(shown, bool) else shown
        shown = ",".join(map(str, shown)) if isinstance(shown, tuple) else shown
        entry = (f"{prefix}{name}={shown}", _type_name(hints[name]), docs.get(name, ""))
        sections[prefix.rstrip(".")].append(entry)
    return sections


def option_entries(options) -> list[tuple[str, str, str]]:
    """A command's own options (a flat dataclass with attribute docstrings) as ``help_text``'s
    ``extra`` entries."""
    return _entries(options)[""]


def help_text(config, usage: str, section: str | None = None, extra: Sequence = ()) -> str:
    """Every key of ``config`` with its default, type and docstring, grouped by section
    (``td3.*``, ``env.*``, ...), under ``usage``; ``section`` narrows it to one group.
    ``extra``: the command's own (key=default, type, docstring) entries, listed first
    (all there is with ``config`` None)."""
    sections = _entries(config) if config is not None else {"": []}
    sections[""] = [*extra, *sections[""]]
    if section is not None:
        name = section.removesuffix(".*").removesuffix(".")
        if name not in sections or not name:
            valid = ", ".join(s for s in sections if s)
            raise ConfigError(f"--help {section}: no such section; sections: {valid}")
        sections = {name: sections[name]}
    lines = [plain(usage.strip()), ""]
    width = 96
    for name, entries in sections.items():
        lines.append(f"{name}.*" if name else "options")
        for key, kind, doc in entries:
            lines.append(f"  {key}  ({kind})")
            if doc:
                pad = " " * 6
                lines += textwrap.wrap(plain(doc), width, initial_indent=pad, subsequent_indent=pad)
        lines.append("")
    return "\n".join(lines).rstrip()
