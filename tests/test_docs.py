"""The documents' commands and keys are ones the commands accept: every ``python -m
solar_jax.<command> ...`` line of README.md and docs/*.md parses with its command's
parser (runs are not started; ``resume=`` lines need a run and are checked for their key
alone), every key the README names as most used exists, and every link to a file in the
repository points at one."""

import re
import shlex

import pytest

from solar_jax import evaluate, plot
from solar_jax.bench import __main__ as bench
from solar_jax.bench import common
from solar_jax.cli import parse_config, parse_overrides, valid_keys
from solar_jax.config import TrainConfig
from solar_jax.experiments import expand
from solar_jax.morphology import get_suite, load
from solar_jax.rollout import RolloutConfig
from solar_jax.sweep import parse_sweep
from tests.conftest import REPO

DOCUMENTS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
COMMAND = re.compile(r"^python -m solar_jax\.(\w+)(.*)$")


def _commands() -> list[tuple[str, str, list[str]]]:
    found = []
    for path in DOCUMENTS:
        for line in path.read_text().splitlines():
            match = COMMAND.match(line.split("#")[0].strip())
            if match:
                found.append((path.name, match[1], shlex.split(match[2])))
    return found


COMMANDS = _commands()


def test_the_documents_show_every_command():
    assert {command for _, command, _ in COMMANDS} >= {
        "train",
        "sweep",
        "plot",
        "evaluate",
        "rollout",
        "morphology",
        "bench",
    }


@pytest.mark.parametrize(
    "document, command, argv", COMMANDS, ids=[f"{d}:{' '.join([c, *a])}" for d, c, a in COMMANDS]
)
def test_every_documented_command_parses(document, command, argv, monkeypatch):
    monkeypatch.chdir(REPO)  # experiment files are given relative to the repository
    if argv[:1] == ["--help"] or any(a.startswith("resume=") for a in argv):
        return  # help: tests/test_commands.py; resume= needs a run: tests/training/test_runner.py
    if command == "train":
        for _, arguments in expand(argv, "train"):
            config = parse_config(arguments)
            get_suite(config.morph)
    elif command == "sweep":
        for _, arguments in expand(argv, "sweep"):
            get_suite(parse_sweep(arguments).config.morph)
    elif command == "plot":
        plot.parse(argv)
    elif command == "evaluate":
        paths, _ = evaluate.parse(argv)
        assert paths, f"{document}: evaluate without a run directory"
    elif command == "rollout":
        load(parse_overrides(RolloutConfig(), argv).morph)
    elif command == "bench":
        part = bench.ALL if argv[0] == "all" else bench.PARTS[argv[0]]
        get_suite(common.parse(argv[1:], part.options)[0].morph)
    elif command == "morphology":
        assert argv[0] in ("list", "show", "build")
        if argv[0] == "show":
            load(argv[1])
    else:
        pytest.fail(f"{document}: no command solar_jax.{command}")


def test_the_readmes_most_used_keys_exist():
    text = (REPO / "README.md").read_text()
    paragraph = text[text.index("Most used keys") :].split("\n\n")[0]
    keys = set(re.findall(r"`([a-z_.0-9]+)=", paragraph))
    assert len(keys) >= 10
    assert keys <= set(valid_keys(TrainConfig)), keys - set(valid_keys(TrainConfig))


@pytest.mark.parametrize("path", DOCUMENTS, ids=[p.name for p in DOCUMENTS])
def test_links_point_at_files_of_the_repository(path):
    for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", path.read_text()):
        if not target.startswith("http"):
            assert (path.parent / target).exists(), f"{path.name}: {target}"
