"""The morphology command line, run as a user would."""

import subprocess
import sys

from tests.conftest import REPO


def _run(*args):
    return subprocess.run(
        [sys.executable, "-m", "solar_jax.morphology", *args],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=120,
    )


def test_list_prints_every_suite_and_robot():
    out = _run("list")
    assert out.returncode == 0, out.stderr
    for line in ("walker++    N_max 7", "whh++       N_max 9", "held out 3: cheetah_3_balanced"):
        assert line in out.stdout
    assert "humanoid_2d_9_full         humanoid_2d  agents 9  actuators 8" in out.stdout
    assert out.stdout.count("  actuators ") == 38


def test_show_prints_tree_distances_and_traversal():
    out = _run("show", "walker_7_main")
    assert out.returncode == 0, out.stderr
    assert "walker_7_main (walker, registry): 7 agents, 6 actuators" in out.stdout
    assert "left3" in out.stdout and "actuator 5 gear 100" in out.stdout
    assert (
        "[[0, 6, 6], [1, 2, 5], [2, 1, 1], [3, 0, 0], [4, 5, 4], [5, 4, 3], [6, 3, 2]]"
        in out.stdout
    )


def test_show_unknown_name_is_one_error_line():
    out = _run("show", "walker_9_main")
    assert out.returncode == 2 and out.stdout == ""
    assert out.stderr.startswith("error: unknown morphology 'walker_9_main'")
    assert out.stderr.count("\n") == 1


def test_build_check_passes_on_the_committed_files():
    out = _run("build", "check=true")
    assert out.returncode == 0, out.stderr
    assert "38 files" in out.stdout


def test_bad_command_lines_are_one_error_line():
    for args, message in (
        ((), "expected one of list, show, build"),
        (("show",), "show: expected show NAME"),
        (("build", "--check"), "'--check': arguments are key=value"),
        (("build", "chek=true"), "unknown config key 'chek'; did you mean check?"),
    ):
        out = _run(*args)
        assert out.returncode == 2 and out.stderr.startswith(f"error: {message}"), out.stderr
        assert out.stderr.count("\n") == 1
    help_ = _run("--help")
    assert help_.returncode == 0 and "check=false" in help_.stdout and "``" not in help_.stdout
