"""``key=value`` overrides onto a typed, frozen config (train, rollout and benchmarks share it).

Nested dataclass fields are addressed with dots (``env.solver_iterations=8``). Values
are parsed by the field's annotated type; an unknown key or a bad value is one error
line that lists what is valid.
"""

import ast
import dataclasses
import inspect
import math
import textwrap
import types
import typing
from collections.abc import Sequence

from solar_jax.config import ConfigError, TrainConfig
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
            valid = ", ".join(valid_keys(type(config), prefix))
            raise ConfigError(f"unknown config key '{prefix}{key}'; valid keys: {valid}")
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


def split_arguments(config_cls, argv: Sequence[str]) -> dict[str, str]:
    """``["a=1", "env.b=2"]`` -> ``{"a": "1", "env.b": "2"}`` (not yet parsed or checked)."""
    overrides = {}
    for arg in argv:
        key, sep, text = arg.partition("=")
        if not sep or not key:
            raise ConfigError(
                f"'{arg}': arguments are key=value; valid keys: {', '.join(valid_keys(config_cls))}"
            )
        overrides[key] = text
    return overrides


def parse_overrides(config, argv: Sequence[str]):
    """``["a=1", "env.b=2"]`` applied onto ``config``."""
    return apply_overrides(config, split_arguments(type(config), argv))


def parse_config(argv: list[str]) -> TrainConfig:
    """The config of a command line.

    ``net=tiny`` (or ``small``) starts from that network preset, ``network.*`` on top. With
    ``resume=RUN_DIR`` the saved run's config is the base, and only the keys in
    ``RESUMABLE`` may be given besides.
    """
    overrides = split_arguments(TrainConfig, argv)
    if "resume" in overrides:
        run_dir = overrides.pop("resume")
        check_resumable(run_dir, overrides, "run")
        base = dataclasses.replace(saved_config(run_dir), resume=run_dir, out=run_dir)
        return apply_overrides(base, overrides)
    base = TrainConfig()
    if "net" in overrides:  # first: network.* apply on top of the preset it selects
        base = apply_overrides(base, {"net": overrides.pop("net")})
    return apply_overrides(base, overrides)


# --------------------------------------------------------------------------------- help
def wants_help(argv: Sequence[str]) -> tuple[bool, str | None]:
    """(asked for help?, the section asked for): ``--help`` or ``--help td3``."""
    if not argv or argv[0] not in HELP_FLAGS:
        return False, None
    return True, (argv[1] if len(argv) > 1 else None)


def field_docs(cls) -> dict[str, str]:
    """A dataclass's attribute docstrings (the string literal under a field), read from
    its source: ``{field: text}``."""
    body = ast.parse(textwrap.dedent(inspect.getsource(cls))).body[0].body
    docs = {}
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
    return getattr(kind, "__name__", str(kind))


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
        entry = (f"{prefix}{name}={shown}", _type_name(hints[name]), docs.get(name, ""))
        sections[prefix.rstrip(".")].append(entry)
    return sections


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
    lines = [usage.strip(), ""]
    width = 96
    for name, entries in sections.items():
        lines.append(f"{name}.*" if name else "options")
        for key, kind, doc in entries:
            lines.append(f"  {key}  ({kind})")
            if doc:
                pad = " " * 6
                lines += textwrap.wrap(doc, width, initial_indent=pad, subsequent_indent=pad)
        lines.append("")
    return "\n".join(lines).rstrip()
