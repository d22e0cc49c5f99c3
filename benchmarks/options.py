"""``key=value`` options of the benchmarks that take no training config."""

import sys
from collections.abc import Sequence

from solar_jax.cli import help_text, wants_help
from solar_jax.config import TrainConfig


def parse_options(argv: Sequence[str], defaults: dict[str, str], doc: str) -> dict[str, str]:
    """``defaults`` with each ``key=value`` of ``argv`` applied. ``--help`` prints the
    module's ``doc`` and the options and exits 0; an unknown key or a missing ``=`` is
    one error line and exit 2."""
    if wants_help(argv)[0]:
        print(help_text(None, doc, extra=[(f"{k}={v}", "str", "") for k, v in defaults.items()]))
        raise SystemExit(0)
    options = dict(defaults)
    for arg in argv:
        key, sep, value = arg.partition("=")
        if not sep or key not in defaults:
            print(
                f"error: {arg!r}: expected key=value with key in {', '.join(defaults)}",
                file=sys.stderr,
            )
            raise SystemExit(2)
        options[key] = value
    return options


def train_help(
    argv: Sequence[str], doc: str, options: Sequence[tuple], defaults: list[str]
) -> bool:
    """``--help`` of a benchmark that takes train's keys: prints the module's ``doc``, its
    own ``options`` and its ``defaults`` beside train's keys (or one section of them).
    True when asked."""
    asked, section = wants_help(argv)
    if asked:
        extra = (*options, ("defaults", "", " ".join(defaults)))
        print(help_text(TrainConfig(), doc, section, extra))
    return asked
