"""The verdicts of the parity benchmarks on hand-made rows: the lockstep envelope and
labels (``benchmarks/lockstep.py``), the closed-loop equivalence test
(``benchmarks/closed_loop_report.py``)."""

import json

from benchmarks import closed_loop_report, lockstep


def _row(iteration, ours, envelope, labels=(0, 1, 2), reference_labels=(0, 1, 2)):
    return {
        "iteration": iteration,
        "ours": {"distance": {"trunk": ours}, "labels": list(labels)},
        "ref32": {"labels": list(reference_labels)},
        "ref64": {"labels": list(reference_labels)},
        "envelope": {"trunk": envelope},
    }


def test_lockstep_verdict_takes_the_worst_ratio_over_rows():
    rows = [_row(0, 0.0, 0.0), _row(100, 2e-7, 1e-7), _row(200, 3e-6, 1e-6)]
    verdict = lockstep.verdict(rows)
    assert verdict["worst_ratio"] == {"trunk": 3.0} and verdict["pass"]
    rows.append(_row(300, 5e-6, 1e-6))  # 5 > ENVELOPE = 4
    assert lockstep.verdict(rows)["worst_ratio"]["trunk"] == 5e-6 / 1e-6
    assert not lockstep.verdict(rows)["pass"]


def test_lockstep_verdict_before_any_rounding_and_on_other_labels():
    # Where the float32 references are still exactly float64, ours must be too (1e-6).
    assert lockstep.verdict([_row(0, 5e-7, 0.0)])["pass"]
    assert not lockstep.verdict([_row(0, 2e-6, 0.0)])["pass"]
    verdict = lockstep.verdict([_row(100, 1e-7, 1e-7, labels=(0, 0, 1))])
    assert verdict["inside"] and not verdict["labels_equal"] and not verdict["pass"]


def test_closed_loop_equivalence_by_hand():
    def run(returns):  # evaluations at 0, 2.5k, 5k: the one at step 0 is not counted
        return [{"env_steps": 2500 * i, "return": r} for i, r in enumerate(returns)]

    ours = {s: run([100, 200 + s, 1200 + s]) for s in range(4)}
    reference = {s: run([9999, 210 + s, 1190 - s]) for s in range(4)}
    reference[4] = run([0, 0, 0])  # a seed the other arm did not finish: left out
    arms = {"1e-3": {"ours": ours, "reference": reference}}
    (row,) = closed_loop_report.compare(arms, 300, min_seeds=4)
    assert row["seeds"] == [0, 1, 2, 3]
    assert row["ours"] == [700.0, 701.0, 702.0, 703.0]
    assert row["reference"] == [700.0, 700.0, 700.0, 700.0]
    assert row["equivalent"] and row["success_ours"] == 4 and row["success_reference"] == 4
    (few,) = closed_loop_report.compare(arms, 300, min_seeds=5)
    assert few["inside_margin"] and not few["equivalent"]
    low, high = row["interval_90"]
    assert low < 1.5 < high and high - low < 5


def test_closed_loop_reads_only_finished_runs(tmp_path):
    def write(name, steps):
        rows = [{"env_steps": s, "return": 100.0 + s / 1000} for s in steps]
        (tmp_path / name).write_text("".join(json.dumps(r) + "\n" for r in rows))

    write("hopper_3_tiny_solar_lr1e-3_ours_seed0.jsonl", [0, 15000, 30012])
    write("hopper_3_tiny_solar_lr1e-3_reference_seed0.jsonl", [0, 15000, 30003])
    write("hopper_3_tiny_solar_lr1e-3_ours_seed1.jsonl", [0, 15000])  # still running
    write("hopper_3_tiny_solar_lr1e-3_reference_seed1.jsonl", [0, 15000, 30100])
    write("hopper_3_tiny_solar_lr1e-3_reference_seed2.jsonl", [])  # just started
    write("hopper_3_small_solar_lr1e-3_ours_seed0.jsonl", [0, 30000])  # another net
    arms = closed_loop_report.load_arms(tmp_path, "hopper_3", "tiny", "solar", 30000)
    assert {agent: sorted(runs) for agent, runs in arms["1e-3"].items()} == {
        "ours": [0],
        "reference": [0, 1],
    }
    (row,) = closed_loop_report.compare(arms, margin=300.0)
    assert row["seeds"] == [0]  # only seeds both arms finished
