"""Curves, synergy drawings and clusters over training from hand-written run directories
(``fake_runs``: straight-line curves with known means)."""

import json

import numpy as np
import pytest
from scipy import stats

from solar_jax.morphology import load
from solar_jax.viz.curves import (
    BAND_SEEDS,
    curve_lines,
    draw_line,
    plot_curves,
    plot_robot_curves,
    robot_lines,
)
from solar_jax.viz.runs import VizError, load_run, load_runs
from solar_jax.viz.synergy import (
    draw_synergies,
    marker_positions,
    plot_clusters,
    robot_geometry,
    synergy_record,
)
from tests.viz.fake_runs import eval_steps, train_return, write_run
from tests.viz.images import assert_image


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """walker++ (two held out): solar at two learning rates (two seeds, one seed) and
    amorpheus; hopper++ (none held out): solar."""
    root = tmp_path_factory.mktemp("runs")
    return load_runs(
        [
            write_run(root / "w0", "walker++", "solar", seed=0, lr=1e-4),
            write_run(root / "w1", "walker++", "solar", seed=1, lr=1e-4),
            write_run(root / "w3", "walker++", "solar", seed=0, lr=3e-4),
            write_run(root / "a0", "walker++", "amorpheus", seed=0, lr=1e-4),
            write_run(root / "h0", "hopper++", "solar", seed=0),
        ]
    )


def test_curve_lines_average_seeds_on_the_common_grid(runs):
    lines = {(line.suite, line.split, line.label): line for line in curve_lines(runs)}
    assert set(lines) == {
        ("walker++", "train", "solar td3.lr=0.0001"),
        ("walker++", "heldout", "solar td3.lr=0.0001"),
        ("walker++", "train", "solar td3.lr=0.0003"),
        ("walker++", "heldout", "solar td3.lr=0.0003"),
        ("walker++", "train", "amorpheus td3.lr=0.0001"),
        ("walker++", "heldout", "amorpheus td3.lr=0.0001"),
        ("hopper++", "train", "solar"),
    }
    two = lines[("walker++", "train", "solar td3.lr=0.0001")]
    assert two.seeds == 2
    assert two.steps[0] == 0 and two.steps[-1] == min(eval_steps(0)[-1], eval_steps(1)[-1])
    # Each seed is a straight line, so interpolation is exact: seeds 0 and 1 are 10 apart.
    expected = (train_return(0, two.steps) + train_return(1, two.steps)) / 2
    np.testing.assert_allclose(two.mean, expected)
    half = stats.t.ppf(0.975, 1) * np.std([0.0, 10.0], ddof=1) / np.sqrt(2)
    np.testing.assert_allclose(two.high - two.mean, half)
    held = lines[("walker++", "heldout", "solar td3.lr=0.0001")]
    np.testing.assert_allclose(held.mean, expected / 2)
    one = lines[("walker++", "train", "solar td3.lr=0.0003")]
    assert one.seeds == 1 and np.array_equal(one.low, one.mean)


def test_episode_curves_come_from_the_round_records(runs):
    line = curve_lines(runs[:1], "episode")[0]
    assert line.split == "train" and line.steps[0] == 250  # the first round, not 0
    np.testing.assert_allclose(line.mean, train_return(0, line.steps) - 1.0)


def test_lines_of_few_seeds_draw_each_seed_as_logged(runs, tmp_path):
    import matplotlib.pyplot as plt

    two = {(line.split, line.label): line for line in curve_lines(runs)}[
        ("train", "solar td3.lr=0.0001")
    ]
    assert two.seeds == 2 < BAND_SEEDS
    fig, ax = plt.subplots()
    draw_line(ax, two, "C0")
    assert not ax.collections  # no band
    for drawn, seed in zip(ax.lines, (0, 1), strict=True):
        np.testing.assert_array_equal(drawn.get_xdata(), eval_steps(seed))  # not the grid
        np.testing.assert_allclose(
            drawn.get_ydata(), train_return(seed, np.array(eval_steps(seed)))
        )
    assert [h.get_label() for h in ax.get_legend_handles_labels()[0]] == [
        "solar td3.lr=0.0001 (n=2)"
    ]
    root = tmp_path / "four"
    four = load_runs([write_run(root / f"s{s}", "hopper++", "solar", seed=s) for s in range(4)])
    (line,) = curve_lines(four)
    fig, ax = plt.subplots()
    draw_line(ax, line, "C0")
    assert len(ax.lines) == 1 and len(ax.collections) == 1  # the mean and its band
    np.testing.assert_array_equal(ax.lines[0].get_xdata(), line.steps)
    plt.close("all")


def test_curves_figure(runs, tmp_path):
    png, svg = plot_curves(runs, tmp_path, "eval")
    assert png.name == "curves-eval.png" and svg.name == "curves-eval.svg"
    assert_image(png)
    text = svg.read_text()
    for expected in (
        "walker++: training morphologies",
        "walker++: held-out morphologies (zero-shot)",
        "hopper++: training morphologies",
        "solar td3.lr=0.0001 (n=2)",
        "amorpheus td3.lr=0.0001 (n=1)",
        "env steps",
        "return",
    ):
        assert expected in text, expected
    assert "hopper++: held-out" not in text
    assert_image(plot_curves(runs, tmp_path, "episode")[0])
    with pytest.raises(VizError, match="metric=best: expected one of eval, episode"):
        plot_curves(runs, tmp_path, "best")


def test_a_panel_per_robot(runs, tmp_path):
    lines = robot_lines(runs)
    walker = [
        li for li in lines if li.suite == "walker++" and li.label.startswith("solar td3.lr=0.0001")
    ]
    names = runs[0].names
    assert [li.split for li in walker] == list(names)  # every robot, held-out ones too
    for i, line in enumerate(walker):  # robot i logs the training return plus 10 i
        first = [li for li in curve_lines(runs) if li.suite == "walker++" and li.split == "train"]
        np.testing.assert_allclose(line.mean, first[0].mean + 10.0 * i)
    png, svg = plot_robot_curves(runs, tmp_path, "eval")
    assert png.name == "curves-eval-robots.png"
    assert_image(png)
    text = svg.read_text()
    assert f"{names[-1]} (held out)" in text and f"{names[0]} (held out)" not in text
    single = load_runs([write_run(tmp_path / "one", "hopper_3", "solar", seed=0)])
    assert plot_robot_curves(single, tmp_path / "single", "eval") == []  # one robot: none


def _distance_to_segments(point: np.ndarray, segments: np.ndarray) -> np.ndarray:
    start, axis = segments[:, 0], segments[:, 1] - segments[:, 0]
    length2 = np.sum(axis * axis, axis=1)  # 0 for capsules along y, seen end on
    along = np.sum((point - start) * axis, axis=1) / np.where(length2 > 0, length2, 1.0)
    t = np.clip(along, 0.0, 1.0)
    return np.linalg.norm(start + t[:, None] * axis - point, axis=1)


def test_robot_geometry_puts_every_joint_on_the_body():
    for name in ("hopper_3", "walker_7_main", "humanoid_2d_9_full", "cheetah_7_full"):
        morph = load(name)
        geometry = robot_geometry(morph)
        assert geometry.joints.shape == (morph.num_agents, 2)
        assert len(geometry.capsules) >= morph.num_agents - 1
        for anchor in geometry.joints:  # inside some capsule
            inside = _distance_to_segments(anchor, geometry.capsules) <= geometry.capsule_radii
            assert inside.any(), (name, anchor)
    hopper = robot_geometry(load("hopper_3"))
    np.testing.assert_allclose(hopper.joints, [[0.0, 1.25], [0.0, 1.05], [0.0, 0.6]])
    np.testing.assert_allclose(hopper.capsules[0], [[0.0, 1.05], [0.0, 1.45]], atol=1e-9)
    assert len(robot_geometry(load("humanoid_2d_9_full")).spheres) > 0


def test_coincident_joints_are_set_side_by_side():
    joints = np.array([[0.0, 1.0], [0.0, 0.5], [0.0, 0.5], [0.2, 0.5], [0.0, 0.5]])
    np.testing.assert_allclose(
        marker_positions(joints, 0.1),
        [[0.0, 1.0], [0.0, 0.5], [0.1, 0.5], [0.2, 0.5], [0.2, 0.5]],
    )
    walker = robot_geometry(load("walker_7_main")).joints  # legs on top of each other
    assert len(np.unique(marker_positions(walker, 0.1), axis=0)) == len(walker)


def test_synergy_drawing(runs, tmp_path):
    walker = runs[0]
    png, svg = draw_synergies(walker, tmp_path)
    last = walker.records_of("round")[-1]["round"]
    assert png.name == f"synergy-w0-round{last}.png"
    assert_image(png)
    text = svg.read_text()
    assert "walker_3_main (held out)" in text and "walker_7_main\n" not in text
    assert "4 synergies" in text  # walker_7_main: torso, then three pairs
    assert "exemplar" in text
    chosen = draw_synergies(walker, tmp_path, round_=3)[0]
    assert chosen.name == "synergy-w0-round3.png"
    assert synergy_record(walker, 3)["round"] == 3
    with pytest.raises(VizError, match=f"no round 999; rounds 1 to {last}"):
        synergy_record(walker, 999)


def test_synergy_drawing_of_a_method_without_synergies_is_an_error(runs, tmp_path):
    amorpheus = runs[3]
    with pytest.raises(VizError, match="method amorpheus has no synergies"):
        draw_synergies(amorpheus, tmp_path)


def test_clusters_over_training(runs, tmp_path):
    png, svg = plot_clusters(runs, tmp_path)  # amorpheus is left out
    assert_image(png)
    text = svg.read_text()
    for expected in ("walker++: solar td3.lr=0.0001 (mean of 2 runs)", "walker_6_main (held out)"):
        assert expected in text, expected
    assert "amorpheus" not in text
    with pytest.raises(VizError, match="no run has synergies"):
        plot_clusters([runs[3]], tmp_path)


def test_unfinished_runs(tmp_path):
    run = write_run(tmp_path / "run")
    lines = (run / "metrics.jsonl").read_text().splitlines()
    (run / "metrics.jsonl").write_text(lines[0] + "\n")  # only the first evaluation
    with pytest.raises(VizError, match="no training round records yet"):
        curve_lines([load_run(run)], "episode")
    with pytest.raises(VizError, match="no training round logged yet"):
        synergy_record(load_run(run))


def test_curves_against_the_run_s_wall_seconds(tmp_path):
    path = write_run(tmp_path / "h", "hopper++", "solar", seed=0)
    records = [json.loads(line) for line in (path / "metrics.jsonl").read_text().splitlines()]
    for r in records:  # 2 s per round, 0.5 s per evaluation, 10 s compiling first
        r["perf/round_s" if r["kind"] == "round" else "perf/eval_s"] = (
            2.0 if r["kind"] == "round" else 0.5
        )
    records[0]["perf/compile_s"] = 10.0
    (path / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    spent = 10.0 + np.cumsum([2.0 if r["kind"] == "round" else 0.5 for r in records])
    at_evals = [s for r, s in zip(records, spent, strict=True) if r["kind"] == "eval"]
    (line,) = curve_lines([load_run(path)], "eval", "wall")
    np.testing.assert_allclose(line.runs[0][0], at_evals)  # one seed: as logged
    np.testing.assert_allclose(
        line.runs[0][1], [r["eval/train_return"] for r in records if r["kind"] == "eval"]
    )
    png, _ = plot_curves([load_run(path)], tmp_path, "eval", "wall")
    assert png.name == "curves-eval-wall.png"
    assert_image(png)
    with pytest.raises(VizError, match="x=minutes: expected one of steps, wall"):
        plot_curves([load_run(path)], tmp_path, "eval", "minutes")
