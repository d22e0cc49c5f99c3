"""``python -m solar_jax.plot`` on a real tiny sweep: the session's two-seed sweep of
``tests.tiny`` (an Euler hopper_3), given as its sweep directory (expanded into its lanes)."""

import os
import subprocess
import sys

import pytest
from PIL import Image

from solar_jax.plot import main
from solar_jax.training.logger import read_metrics
from tests.conftest import REPO
from tests.viz.images import assert_image


@pytest.fixture
def sweep_dir(tiny_sweep):
    return tiny_sweep[0]


@pytest.fixture
def runs(sweep_dir):
    return [sweep_dir / "seed0", sweep_dir / "seed1"]


def test_all_figures_of_two_seeds(sweep_dir, runs, tmp_path, capsys):
    assert main(["all", str(sweep_dir), f"out={tmp_path}"]) == 0
    written = capsys.readouterr().out.split()
    pngs = sorted(path.rsplit("/", 1)[-1] for path in written if path.endswith(".png"))
    rounds = [read_metrics(run)[-2]["round"] for run in runs]  # the last round, then its eval
    assert pngs == sorted(
        [
            "curves-eval.png",
            "clusters.png",
            f"synergy-seed0-round{rounds[0]}.png",
            f"synergy-seed1-round{rounds[1]}.png",
        ]
    )
    for name in pngs:
        assert_image(tmp_path / name)
    assert "solar (n=2)" in (tmp_path / "curves-eval.svg").read_text()


def test_rollout_video(runs, tmp_path):
    """In a fresh process: MuJoCo takes its OpenGL backend from MUJOCO_GL when first
    imported, and this session imported it long before (the command sets egl first)."""
    out = tmp_path / "hopper.gif"
    argv = ["video", str(runs[0]), "steps=50", "width=96", "height=64", f"out={out}"]
    result = subprocess.run(
        [sys.executable, "-m", "solar_jax.plot", *argv],
        capture_output=True,
        text=True,
        cwd=REPO,
        env={k: v for k, v in os.environ.items() if k != "MUJOCO_GL"},
        timeout=600,
    )
    if result.returncode == 2 and "no OpenGL context" in result.stderr:
        pytest.skip(result.stderr.strip())
    assert result.returncode == 0, result.stderr[-3000:]
    assert result.stdout.split()[-1] == str(out)
    assert_image(out)
    with Image.open(out) as gif:
        assert gif.size == (96, 64)
        # Every 4th of at most 51 states (hopper: 125 steps/s, shown at ~30 frames/s).
        assert 1 <= gif.n_frames <= 13
