"""``python -m solar_jax.plot`` on hand-written runs: what it writes, and one error line
(exit 2) for each kind of bad input."""

import os
import subprocess
import sys

import mujoco
import pytest

from solar_jax.plot import main
from tests.conftest import REPO
from tests.viz.fake_runs import write_run, write_sweep
from tests.viz.images import assert_image


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    root = tmp_path_factory.mktemp("cli")
    write_run(root / "solar", "walker++", "solar")
    write_run(root / "amorpheus", "walker++", "amorpheus")
    write_sweep(root / "sweep", [{"seed": 0, "lr": 1e-4}, {"seed": 1, "lr": 3e-4}], "hopper++")
    write_run(root / "no_metrics")
    (root / "no_metrics" / "metrics.jsonl").unlink()
    (root / "empty").mkdir()
    return root


def test_all_plots_runs_and_sweeps_and_notes_runs_without_synergies(root, tmp_path, capsys):
    argv = [str(root / "solar"), str(root / "amorpheus"), str(root / "sweep"), f"out={tmp_path}"]
    assert main(argv) == 0  # "all" is the default
    captured = capsys.readouterr()
    written = captured.out.split()
    names = sorted(os.path.basename(path) for path in written)
    assert names == sorted(
        [
            "curves-eval.png",
            "curves-eval.svg",
            "curves-eval-robots.png",  # a panel per robot of each suite
            "curves-eval-robots.svg",
            "synergy-solar-round20.png",
            "synergy-solar-round20.svg",
            "synergy-lane0-round20.png",
            "synergy-lane0-round20.svg",
            "synergy-lane1-round20.png",
            "synergy-lane1-round20.svg",
            "clusters.png",
            "clusters.svg",
        ]
    )
    for path in written:
        if path.endswith(".png"):
            assert_image(tmp_path / os.path.basename(path))
    assert "amorpheus" in captured.err and "has no synergies" in captured.err


def test_default_out_is_the_run_directory(root, capsys):
    assert main(["curves", str(root / "sweep"), "metric=episode"]) == 0
    assert capsys.readouterr().out.split() == [
        str(root / "sweep" / "plots" / "curves-episode.png"),
        str(root / "sweep" / "plots" / "curves-episode.svg"),
    ]


@pytest.mark.parametrize(
    "argv, message",
    [
        ([], "no run directories given"),
        (["curves"], "no run directories given"),
        (["{root}/empty"], "not a run directory (no config.json) nor a sweep directory"),
        (["{root}/nowhere"], "not a run directory"),
        (["{root}/no_metrics"], "no metrics.jsonl"),
        (["{root}/solar", "colour=red"], "unknown config key 'colour'; keys: out, metric"),
        (["curves", "{root}/solar", "metric=best"], "metric=best: expected one of eval, episode"),
        (
            ["curves", "{root}/solar", "round=3"],
            "curves does not take round=; it takes out, metric",
        ),
        (["synergy", "{root}/amorpheus"], "method amorpheus has no synergies"),
        (["synergy", "{root}/solar", "round=999"], "no round 999; rounds 1 to 20"),
        (["clusters", "{root}/amorpheus"], "no run has synergies (methods: amorpheus"),
        (["video", "{root}/solar", "{root}/amorpheus"], "video takes one run directory, got 2"),
        (["video", "{root}/solar", "steps=0"], "steps must be >= 1"),
        (["video", "{root}/solar", "out=a.avi"], "out=a.avi: expected a .gif or .mp4 file"),
        (["video", "{root}/solar", "morph=hopper_3"], "morph=hopper_3: not in this run's suite"),
        (["video", "{root}/solar", "metric=eval"], "video does not take metric="),
    ],
)
def test_bad_input_is_one_clear_error(root, argv, message, capsys):
    assert main([arg.format(root=root) for arg in argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and message in err and err.count("\n") == 1, err


def test_video_without_checkpoints_is_one_clear_error(root, capsys, monkeypatch):
    monkeypatch.setattr(mujoco, "Renderer", lambda *a, **k: _Closed())
    assert main(["video", str(root / "solar")]) == 2
    err = capsys.readouterr().err
    assert "no checkpoints/ to take a policy from" in err and err.count("\n") == 1, err


class _Closed:
    def close(self) -> None:
        pass


def test_no_opengl_is_one_clear_error(root, capsys, monkeypatch):
    def fail(*args, **kwargs):
        raise mujoco.FatalError("gladLoadGL error")

    monkeypatch.setattr(mujoco, "Renderer", fail)
    monkeypatch.setenv("MUJOCO_GL", "egl")
    assert main(["video", str(root / "solar")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    for part in ("cannot render", "MUJOCO_GL=egl", "FatalError: gladLoadGL error", "libEGL"):
        assert part in err, part


def test_no_opengl_backend_in_a_fresh_process(root):
    """MuJoCo's own failure without a backend (MUJOCO_GL=disable): still one line."""
    result = subprocess.run(
        [sys.executable, "-m", "solar_jax.plot", "video", str(root / "solar")],
        capture_output=True,
        text=True,
        cwd=REPO,
        env={**os.environ, "MUJOCO_GL": "disable"},
        timeout=300,
    )
    assert result.returncode == 2, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and "no OpenGL context with MUJOCO_GL=disable" in lines[0], lines
