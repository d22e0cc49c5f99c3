"""Faults a hostile user, a full disk or a kill meets, one test each (numbered as in the
probe's list; docs/training.md, "Resume, faults and bad input"): nothing hangs, nothing is
lost or mixed, nothing is written outside the run, and every one is one line, exit 2 for a bad input
and 1 for a fault.

The runs are ``tests.tiny``'s and share the session's compiled round (``tiny_run``); the
finished run that several tests damage is run once per module and copied per test.
"""

import dataclasses
import errno
import json
import os
import pickle
import re
import shutil
import signal
import subprocess
import sys
import threading
from pathlib import Path

import jax
import numpy as np
import orbax.checkpoint as ocp
import pytest

from solar_jax import sweep, train
from solar_jax.cli import parse_config
from solar_jax.config import ConfigError
from solar_jax.experiments import one_line_errors
from solar_jax.plot import main as plot_main
from solar_jax.sweep import parse_sweep
from solar_jax.training import rundir
from solar_jax.training.checkpoint import Checkpointer, CheckpointError
from solar_jax.training.logger import MetricsError, MetricsLog, read_metrics
from solar_jax.training.rundir import CHECKPOINTS, LOCK_FILE, RunDirError, RunLock
from solar_jax.training.runner import Runner, health_problem, restore_run
from solar_jax.training.trainer import RoundStats
from solar_jax.xla import cache, times
from solar_jax.xla import programs as xla_programs
from tests.conftest import REPO
from tests.tiny import ARGS, CONFIG, Killed


def _without_timings(records: list[dict]) -> list[dict]:
    return [{k: v for k, v in r.items() if not k.startswith("perf/")} for r in records]


@pytest.fixture
def programs(tiny_run):
    return tiny_run


@pytest.fixture(scope="module")
def finished(tmp_path_factory, tiny_run):
    """A finished 700-step run whose replay grew (1024 -> 2048 slots), its last two
    checkpoints kept: (directory, records without timings)."""
    run_dir = tmp_path_factory.mktemp("finished") / "run"
    config = dataclasses.replace(CONFIG, total_steps=700, checkpoint_every=300, out=str(run_dir))
    state = Runner(config, tiny_run).run()
    assert state.replay.capacity == 2048
    assert len(rundir.checkpoint_steps(run_dir)) == 2
    return run_dir, _without_timings(read_metrics(run_dir))


@pytest.fixture
def run_copy(finished, tmp_path) -> Path:
    return Path(shutil.copytree(finished[0], tmp_path / "run"))


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


# ------------------------------------------------- 1, 2: runs that never end, numbers
def test_1_a_diverging_run_stops_at_its_first_bad_round_and_saves_none_of_it(
    tmp_path, programs, capsys
):
    td3 = dataclasses.replace(CONFIG.td3, lr=1e30)  # Adam steps of 1e30: inf, then NaN
    config = dataclasses.replace(CONFIG, total_steps=3000, td3=td3, out=str(tmp_path / "run"))
    rounds = []

    def bounded(state, records):
        rounds.append(records)
        assert len(rounds) < 30, "the diverged run went on"

    runner = Runner(config, programs)
    runner.run(on_round=bounded)
    assert len(runner.failures) == 1
    line = _one_error_line(capsys)
    assert re.search(r"round \d+: non-finite losses or parameters", line), line
    assert "no checkpoint was saved" in line and rundir.checkpoint_steps(tmp_path / "run") == []
    # A round that counts no step (every episode ended at once) stops a lane too.
    stats = RoundStats(
        episode_return=np.zeros(1),
        episode_length=np.ones(1),
        steps=np.zeros(1),
        episodes=np.ones(1),
    )
    healthy = {"finite": True, "critic_loss": 1.0, "actor_loss": 1.0}
    assert "no env step counted" in health_problem(healthy, stats)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["td3.lr=inf"], "td3.lr must be a finite number, got inf"),
        (["td3.exploration_noise=nan"], "td3.exploration_noise must be a finite number"),
        (["td3.policy_noise=inf"], "td3.policy_noise must be a finite number"),
        (["td3.grad_clip=inf"], "td3.grad_clip must be a finite number"),
        (["td3.action_penalty=nan"], "td3.action_penalty must be a finite number"),
        (["seed=2147483648"], "seed=2147483648: integers must be within"),
        (["seed=-1"], "seed must be >= 0"),
        (["total_steps=2.5"], "total_steps=2.5: expected int"),
        (["total_steps=2e9"], "total_steps must be <= 1,000,000,000"),
        (["env.max_episode_steps=1"], "env.max_episode_steps must be >= 2"),
        (["env.variation=density=-1:1"], "variation density: range -1:1 must be positive"),
        (["env.variation=stiffness"], "unknown variation property 'stiffness'"),
        (["env.variation=all", "env.variation_pool=0"], "env.variation_pool must be >= 1"),
    ],
)
def test_2_numbers_out_of_range_are_one_error_line(argv, message, capsys):
    assert train.main(["morph=hopper_3", "dry_run=true", *argv]) == 2
    assert message in _one_error_line(capsys)


def test_2_the_examples_of_the_help_parse():
    examples = re.findall(r"``([\w.]+=[^`\s\[]+)``", f"{train.__doc__} {sweep.__doc__}")
    assert "total_steps=2e6" in examples
    for example in examples:
        if not example.startswith(("seeds=", "resume=")) and not example.endswith("/"):
            parse_config([example])
    assert parse_config(["total_steps=2e6"]).total_steps == 2_000_000


# --------------------------------------------------------- 3-8: data lost or mixed
def test_3_a_torn_last_line_is_skipped_by_resume_and_plot(run_copy, finished, capsys):
    with (run_copy / rundir.METRICS_FILE).open("a") as f:
        f.write('{"kind": "round", "round": 9, "env_st')  # the disk filled mid-line
    assert _without_timings(read_metrics(run_copy)) == finished[1]
    assert "its last line is torn" in capsys.readouterr().err
    MetricsLog(run_copy, keep_rounds=finished[1][-1]["round"]).close()  # what resume does
    text = (run_copy / rundir.METRICS_FILE).read_text()
    assert text.endswith("}\n") and "env_st\n" not in text
    assert plot_main(["curves", str(run_copy), f"out={run_copy / 'plots'}"]) == 0
    # A damaged line before the last is not a cut write: one error line, exit 1.
    lines = text.splitlines()
    (run_copy / rundir.METRICS_FILE).write_text("\n".join([lines[0], "garbage", *lines[1:]]))
    with pytest.raises(MetricsError, match="line 2 is damaged"):
        read_metrics(run_copy)
    assert plot_main(["curves", str(run_copy)]) == 1
    assert "line 2 is damaged" in _one_error_line(capsys)


def test_4_out_never_deletes_a_run_it_did_not_write(run_copy, programs):
    shutil.rmtree(run_copy / CHECKPOINTS)  # a finished run, checkpoints deleted for space
    before = (run_copy / rundir.METRICS_FILE).read_text()
    with pytest.raises(ConfigError, match=r"already holds a run \(config.json, metrics.jsonl\)"):
        Runner(dataclasses.replace(CONFIG, out=str(run_copy)), programs).run()
    assert (run_copy / rundir.METRICS_FILE).read_text() == before


def test_5_a_run_directory_has_one_writer(tmp_path, programs, capsys):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    owner = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        lock = {"pid": owner.pid, "host": RunLock(run_dir).owner["host"]}
        (run_dir / LOCK_FILE).write_text(json.dumps(lock))
        with pytest.raises(RunDirError, match=f"in use by process {owner.pid} on"):
            Runner(dataclasses.replace(CONFIG, out=str(run_dir)), programs).run()
        assert sorted(p.name for p in run_dir.iterdir()) == [LOCK_FILE]  # nothing written
    finally:
        owner.kill()
        owner.wait()
    # Its owner is gone (a crash): the lock is stale, taken over and said so.
    with RunLock(run_dir):
        assert json.loads((run_dir / LOCK_FILE).read_text())["pid"] == os.getpid()
        with pytest.raises(RunDirError, match=f"in use by process {os.getpid()}"):
            RunLock(run_dir).acquire()
    assert "its process is gone; taking the lock over" in capsys.readouterr().out
    assert not (run_dir / LOCK_FILE).exists()  # released


def test_6_lanes_of_equal_values_are_refused_and_names_are_unique():
    base = ["morph=hopper_3", "net=tiny", "seeds=1", "out=/tmp/unused-sweep"]
    with pytest.raises(ConfigError, match="a value is repeated"):
        parse_sweep([*base, "td3.lr=[1e-4,0.0001]"])
    close = parse_sweep([*base, "td3.lr=[1e-4,1.0000001e-4]"])
    names = [lane.name for lane in close.lanes]
    assert len(set(names)) == 2, names


def test_7_a_run_killed_writing_its_first_checkpoint_resumes(tmp_path, programs, monkeypatch):
    straight = tmp_path / "straight"
    Runner(dataclasses.replace(CONFIG, out=str(straight)), programs).run()
    killed = tmp_path / "killed"
    save = Checkpointer.save

    def killed_writing(self, step, *args, **kwargs):  # orbax's temporary folder, half done
        (self.directory / f"{step}.orbax-checkpoint-tmp-1733000000").mkdir(parents=True)
        raise Killed

    monkeypatch.setattr(Checkpointer, "save", killed_writing)
    with pytest.raises(Killed):
        Runner(dataclasses.replace(CONFIG, out=str(killed)), programs).run()
    monkeypatch.setattr(Checkpointer, "save", save)
    assert not rundir.has_checkpoint(killed)
    with pytest.raises(ConfigError, match="continue it with resume="):
        Runner(dataclasses.replace(CONFIG, out=str(killed)), programs).run()
    Runner(parse_config([f"resume={killed}"]), programs).run()  # starts over
    assert _without_timings(read_metrics(killed)) == _without_timings(read_metrics(straight))
    assert (killed / f"{rundir.METRICS_FILE}.before-restart").exists()  # nothing deleted


_KILLED_WRITING = """
import os, signal, sys
from solar_jax.training.checkpoint import Checkpointer

def killed_writing(self, step, *args, **kwargs):  # orbax's temporary folder, then SIGKILL
    (self.directory / f"{step}.orbax-checkpoint-tmp-1733000000").mkdir(parents=True)
    os.kill(os.getpid(), signal.SIGKILL)

Checkpointer.save = killed_writing
from solar_jax.train import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.slow  # two command-line runs (~30 s on 2 cores, their programs from the cache)
def test_7_a_child_killed_by_sigkill_in_its_first_checkpoint_resumes(tmp_path, programs):
    straight = tmp_path / "straight"
    Runner(dataclasses.replace(CONFIG, out=str(straight)), programs).run()
    killed = tmp_path / "killed"
    args = [*ARGS, "plots=false", f"out={killed}"]
    child = subprocess.run([sys.executable, "-c", _KILLED_WRITING, *args], cwd=REPO, timeout=600)
    assert child.returncode == -signal.SIGKILL
    assert (killed / LOCK_FILE).exists() and not rundir.has_checkpoint(killed)
    resumed = subprocess.run(
        [sys.executable, "-m", "solar_jax.train", f"resume={killed}"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert "its process is gone; taking the lock over" in resumed.stdout  # the stale lock
    assert "holds no complete checkpoint; the run starts over" in resumed.stdout
    assert _without_timings(read_metrics(killed)) == _without_timings(read_metrics(straight))
    assert not (killed / LOCK_FILE).exists()


def test_8_an_edited_config_json_is_refused_on_resume(run_copy, programs):
    path = run_copy / rundir.CONFIG_FILE
    saved = json.loads(path.read_text())
    saved["config"]["td3"]["grad_clip"] = 0.5
    path.write_text(json.dumps(saved))
    with pytest.raises(ConfigError, match=r"td3.grad_clip 0.5 \(checkpoint: 0.1\)"):
        Runner(parse_config([f"resume={run_copy}", "total_steps=900"]), programs).run()


# ------------------------------------------------- 9-12: one line, not a traceback
@pytest.mark.parametrize(
    "text, message",
    [
        ("{not json", "damaged, not JSON"),
        ('{"resolved": {}}', "damaged, no 'config' section"),
        ('{"config": {"seed": "zero"}}', "seed='zero': expected int"),
        ('{"config": {"td3": {"lr": null}}}', "td3.lr=None: expected float"),
        ('{"config": {"colour": 1}}', "unknown TrainConfig keys ['colour']"),
        ('["config"]', "damaged, not a JSON object"),
    ],
)
def test_9_a_damaged_config_json_is_one_line(tmp_path, text, message, capsys):
    (tmp_path / rundir.CONFIG_FILE).write_text(text)
    (tmp_path / rundir.METRICS_FILE).write_text('{"kind": "eval", "round": 0}\n')
    assert train.main([f"resume={tmp_path}"]) == 2
    line = _one_error_line(capsys)
    assert message in line and str(tmp_path / rundir.CONFIG_FILE) in line, line
    # plot reads only what it shows: here every file lacks its "resolved" section.
    assert plot_main(["curves", str(tmp_path), f"out={tmp_path / 'plots'}"]) == 2
    assert f"{tmp_path / rundir.CONFIG_FILE}: damaged" in _one_error_line(capsys)


def _damage(checkpoint: Path, how: str) -> None:
    if how == "truncated":
        for path in (checkpoint / "state").rglob("*"):
            if path.is_file() and path.stat().st_size > 16:
                path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    elif how == "state removed":
        shutil.rmtree(checkpoint / "state")
    else:  # its metadata cut
        meta = checkpoint / "meta" / "metadata"
        meta.write_bytes(meta.read_bytes()[:20])


@pytest.mark.parametrize("how", ["truncated", "state removed", "meta cut"])
def test_10_a_damaged_latest_checkpoint_falls_back_to_the_one_before(
    run_copy, finished, programs, how, capsys
):
    older, latest = rundir.checkpoint_steps(run_copy)
    _damage(run_copy / CHECKPOINTS / str(latest), how)
    config = parse_config([f"resume={run_copy}"])
    for writer in (False, True):  # a reader (a video) moves nothing; a resume sets aside
        state, meta, checkpointer = restore_run(programs.trainer, config, run_copy, writer)
        checkpointer.close()
        assert meta["step"] == older and int(state.rounds) == older
        assert f"checkpoint {run_copy.absolute() / CHECKPOINTS / str(latest)} is damaged" in (
            capsys.readouterr().err
        )
        kept = [older] if writer else [older, latest]
        assert rundir.checkpoint_steps(run_copy) == kept  # the damaged one set aside
    assert (run_copy / "damaged_checkpoints" / str(latest)).is_dir()
    if how == "truncated":  # the resumed run writes that step again, and ends as before
        Runner(config, programs).run()
        assert _without_timings(read_metrics(run_copy)) == finished[1]
    for step in rundir.checkpoint_steps(run_copy):
        _damage(run_copy / CHECKPOINTS / str(step), how)
    with pytest.raises(CheckpointError, match="no readable checkpoint in"):
        restore_run(programs.trainer, config, run_copy)


def test_11_unwritable_places_are_one_line_and_leave_nothing_half_written(
    tmp_path, programs, monkeypatch, capsys
):
    a_file = tmp_path / "a_file"
    a_file.write_text("mine")
    for out, message in [
        (a_file, "a file of that name is in the way"),
        (a_file / "run", "cannot be created"),
        (Path("/proc/solar_jax_run"), "cannot be created"),
    ]:
        with pytest.raises(RunDirError, match=message):
            Runner(dataclasses.replace(CONFIG, out=str(out)), programs).run()
    assert a_file.read_text() == "mine"

    # A full disk at the start: no config.json at all, not an empty one.
    def full(self, *args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(Path, "write_text", full)
    monkeypatch.setattr(Path, "write_bytes", full)
    with pytest.raises(RunDirError, match="config.json: cannot be written .No space left"):
        Runner(dataclasses.replace(CONFIG, out=str(tmp_path / "full")), programs).run()
    monkeypatch.undo()
    assert sorted(p.name for p in (tmp_path / "full").iterdir()) == []
    # A full disk during a checkpoint: one line; the checkpoints before it are intact.
    checkpointer = Checkpointer(tmp_path / "checkpoints")
    checkpointer.save(1, {"x": np.ones(3)}, {})
    monkeypatch.setattr(ocp.CheckpointManager, "save", full)
    with pytest.raises(RunDirError, match="checkpoint .*/2 cannot be written .No space left"):
        checkpointer.save(2, {"x": np.ones(3)}, {})
    monkeypatch.undo()
    assert checkpointer.restore({"x": np.ones(3)})[1]["step"] == 1
    checkpointer.close()
    # A cache folder that cannot be written: a warning, and the run goes on without it.
    monkeypatch.setenv("SOLAR_JAX_CACHE", str(a_file / "cache"))
    try:
        assert cache.enable_compilation_cache() is None
        assert "cannot write there" in capsys.readouterr().err
    finally:
        monkeypatch.undo()
        cache.enable_compilation_cache()
    # The commands' exit codes: 2 for a bad input, 1 for a fault.
    for error, code in [(ConfigError("bad"), 2), (RunDirError("fault"), 1), (OSError(5, "io"), 1)]:

        def fails(arguments, error=error):
            raise error

        assert one_line_errors(fails, []) == code
        _one_error_line(capsys)


def test_12_concurrent_writers_of_the_compile_times_never_collide(tmp_path, monkeypatch):
    monkeypatch.setenv("SOLAR_JAX_CACHE", str(tmp_path))
    errors = []

    def writer(i):
        try:
            for j in range(40):
                times.save_compile_time(f"program-{i}-{j}", 1.0)
        except Exception as err:  # what the test looks for
            errors.append(err)

    threads = [threading.Thread(target=writer, args=(i,)) for i in range(6)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert errors == []
    assert json.loads((tmp_path / times.TIMES_FILE).read_text())
    assert not list(tmp_path.glob("*.tmp"))


# --------------------------------------------------------- 13: a run that can be shown
def test_13_a_video_restores_a_run_whose_replay_grew(finished):
    from solar_jax.viz.video import restore

    run_dir, records = finished
    _, state, step = restore(run_dir)
    assert state.replay.capacity == 2048 and step == records[-1]["round"]


# ------------------------------------------------------------------- 14, 15: security
def test_14_a_crafted_sweep_json_cannot_reach_outside_the_sweep(tmp_path, capsys):
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / rundir.METRICS_FILE).write_text("precious\n")
    directory = tmp_path / "sweep"
    directory.mkdir()
    saved = parse_sweep(["morph=hopper_3", "net=tiny", "seeds=2", f"out={directory}"]).to_dict()
    (directory / rundir.SWEEP_FILE).write_text(json.dumps(saved | {"seeds": ["/../../victim"]}))
    with pytest.raises(ConfigError, match=re.escape("seed '/../../victim': expected an int")):
        parse_sweep([f"resume={directory}"])
    crafted = saved | {"grid": {"td3.lr": ["/../../victim"]}}
    (directory / rundir.SWEEP_FILE).write_text(json.dumps(crafted))
    with pytest.raises(ConfigError, match="not a sweepable number"):
        parse_sweep([f"resume={directory}"])
    lanes = saved["lanes"] + [{"run_dir": "../victim"}]
    (directory / rundir.SWEEP_FILE).write_text(json.dumps(saved | {"lanes": lanes}))
    assert plot_main(["curves", str(directory)]) == 2
    assert "a lane's run_dir is not a folder name" in _one_error_line(capsys)
    assert (victim / rundir.METRICS_FILE).read_text() == "precious\n"
    assert sorted(p.name for p in victim.iterdir()) == [rundir.METRICS_FILE]


class _Payload:
    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (Path.touch, (self.marker,))


def test_15_the_program_cache_runs_no_code_from_its_files(tmp_path, monkeypatch):
    marker = tmp_path / "code_ran"
    programs = tmp_path / "programs"
    programs.mkdir()
    monkeypatch.setattr(cache, "programs_dir", programs)
    args = (jax.ShapeDtypeStruct((3,), np.float32),)

    def double(x):
        return {"y": x * 2}

    xla_programs.compile_program(double, args, fingerprint="test-15")
    (saved,) = programs.iterdir()
    assert saved.read_bytes().startswith(b"solar_jax program\n")
    # Anyone who can write the folder replaces the file with a pickle that runs code.
    saved.write_bytes(pickle.dumps((_Payload(marker), None)))
    program = xla_programs.compile_program(double, args, fingerprint="test-15")
    assert not marker.exists()  # read as a damaged file, traced again
    np.testing.assert_array_equal(program(np.ones(3, np.float32))["y"], 2 * np.ones(3))
    assert saved.read_bytes().startswith(b"solar_jax program\n")  # and rewritten
