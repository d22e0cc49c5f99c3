"""The fault probe: each fault of the robustness list (tests/test_faults.py, numbered the
same) tried as a user meets it, through the commands in child processes.

    python benchmarks/fault_probe.py [repo=.] [tag=NAME] [timeout=120] [out=DIR]

``repo=PATH`` probes another checkout's code (its ``solar_jax``, e.g. a worktree of an
older commit: the before of a before/after table). Each probe records what the user
saw: the exit code, whether a traceback was printed, the last line on stderr, whether
it ran past ``timeout`` seconds (a run that never ends), and what happened to the files
(lost, mixed, written outside). Runs are ``hopper_3`` with tiny networks, one shared
compilation cache per probe. Full disks are not probed here (they need a mount; the
tests patch the writers instead). Prints a table and writes
``fault_probe[_<tag>].json`` into ``out`` (default ``benchmarks/results/``).
"""

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.options import parse_options  # noqa: E402

OPTIONS = {"repo": ".", "tag": "", "timeout": "120", "out": ""}
RESULTS = Path(__file__).resolve().parent / "results"
TINY = ["morph=hopper_3", "net=tiny", "progress=false", "plots=false"]  # the run


class Probe:
    """Child processes of one checkout's commands, in one scratch folder and cache."""

    def __init__(self, repo: Path, root: Path, timeout: float):
        self.repo, self.root, self.timeout = repo, root, timeout
        self.env = os.environ | {
            "PYTHONPATH": str(repo),
            "SOLAR_JAX_CACHE": str(root / "cache"),
            "MUJOCO_GL": "egl",
        }

    def start(self, module: str, *args: str, env: dict | None = None) -> subprocess.Popen:
        command = [sys.executable, "-m", f"solar_jax.{module}", *args]
        return subprocess.Popen(
            command,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            cwd=self.root,
            env=self.env | (env or {}),
        )

    def finish(self, child: subprocess.Popen) -> dict:
        start = time.perf_counter()
        try:
            out, err = child.communicate(timeout=self.timeout)
        except subprocess.TimeoutExpired:
            child.kill()
            out, err = child.communicate()
            return {"rc": None, "hang": True, "traceback": False, "line": "(killed: timeout)"}
        lines = [line for line in err.splitlines() if line.strip()]
        printed = [line for line in out.splitlines() if line.strip()]
        return {
            "rc": child.returncode,
            "hang": False,
            "traceback": "Traceback" in err,
            "line": lines[-1][:200] if lines else "",
            "stdout": printed[-1][:200] if printed else "",
            "seconds": round(time.perf_counter() - start, 1),
        }

    def run(self, module: str, *args: str, env: dict | None = None) -> dict:
        return self.finish(self.start(module, *args, env=env))

    def python(self, code: str) -> dict:
        child = subprocess.Popen(
            [sys.executable, "-c", code],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            cwd=self.root,
            env=self.env,
        )
        return self.finish(child)

    def copy(self, run: Path, name: str) -> Path:
        return Path(shutil.copytree(run, self.root / name))


def _records(run_dir: Path) -> int:
    path = run_dir / "metrics.jsonl"
    return len(path.read_text().splitlines()) if path.exists() else 0


def probes(p: Probe) -> list[dict]:
    """Every probe's outcome: {fault, case, rc, traceback, hang, line, files}."""
    rows = []

    def row(fault: int, case: str, outcome: dict, files: str = "") -> None:
        rows.append({"fault": fault, "case": case, **outcome, "files": files})
        print(f"{fault:>2} {case}: {outcome} {files}", flush=True)

    finished = p.root / "finished"  # 3000 steps: the replay grows past its first 2048 slots
    outcome = p.run("train", *TINY, "total_steps=3000", "checkpoint_every=1000", f"out={finished}")
    assert outcome["rc"] == 0, outcome

    # 1: a diverging run.
    nan = p.root / "nan"
    outcome = p.run("train", *TINY, "total_steps=3000", "td3.lr=1e3", f"out={nan}")
    checkpoints = sorted(x.name for x in (nan / "checkpoints").glob("*")) if nan.exists() else []
    row(1, "td3.lr=1e3", outcome, f"{_records(nan)} records, checkpoints {checkpoints}")
    # 2: numbers.
    for arg in (
        "td3.lr=inf",
        "td3.exploration_noise=nan",
        "td3.policy_noise=inf",
        "td3.grad_clip=inf",
        "td3.action_penalty=nan",
        "seed=2147483648",
        "env.max_episode_steps=1",
        "total_steps=2e6",
    ):
        row(2, arg, p.run("train", *TINY, "dry_run=true", arg))
    # 3: a torn last line of metrics.jsonl.
    torn = p.copy(finished, "torn")
    with (torn / "metrics.jsonl").open("a") as f:
        f.write('{"kind": "round", "round": 99, "env_st')
    row(3, "resume=", p.run("train", f"resume={torn}", "total_steps=3200"))
    row(3, "plot", p.run("plot", "curves", str(torn), f"out={p.root / 'plots3'}"))
    # 4: out= over a finished run whose checkpoints were deleted.
    deleted = p.copy(finished, "deleted")
    shutil.rmtree(deleted / "checkpoints")
    before = _records(deleted)
    outcome = p.run("train", *TINY, "total_steps=300", f"out={deleted}")
    row(4, "out= (no checkpoints)", outcome, f"records {before} -> {_records(deleted)}")
    # 5: two trains on one out=.
    twice = p.root / "twice"
    first = p.start("train", *TINY, "total_steps=1500", f"out={twice}")
    second = p.start("train", *TINY, "total_steps=1500", f"out={twice}")
    a, b = p.finish(first), p.finish(second)
    row(
        5,
        "two trains, one out=",
        {"rc": (a["rc"], b["rc"])} | {k: b[k] for k in ("hang", "traceback", "line")},
        f"{_records(twice)} records",
    )
    # 6: two swept values equal to six digits.
    sweep = p.root / "sweep6"
    outcome = p.run(
        "sweep", *TINY, "seeds=1", "td3.lr=[1e-4,0.0001]", "total_steps=200", f"out={sweep}"
    )
    lanes = sorted(x.name for x in sweep.iterdir() if x.is_dir()) if sweep.exists() else []
    row(6, "td3.lr=[1e-4,0.0001]", outcome, f"lane directories {lanes}")
    # 7: killed while writing the first checkpoint (the state it leaves, reproduced).
    dead = p.copy(finished, "dead")
    shutil.rmtree(dead / "checkpoints")
    (dead / "checkpoints" / "5.orbax-checkpoint-tmp-1733000000").mkdir(parents=True)
    row(7, "resume=", p.run("train", f"resume={dead}"), f"{_records(dead)} records")
    row(7, "out=", p.run("train", *TINY, f"out={dead}"))
    # 8: config.json edited by hand.
    edited = p.copy(finished, "edited")
    saved = json.loads((edited / "config.json").read_text())
    saved["config"]["td3"]["grad_clip"] = 0.5
    (edited / "config.json").write_text(json.dumps(saved))
    row(8, "td3.grad_clip edited, resume=", p.run("train", f"resume={edited}", "total_steps=3200"))
    # 9: damaged config.json.
    for case, text in (
        ("bad JSON", "{not json"),
        ("no config key", '{"resolved": {}}'),
        ("a wrong type", None),
        ("an unknown key", None),
    ):
        damaged = p.copy(finished, f"damaged-{case.replace(' ', '-')}")
        saved = json.loads((damaged / "config.json").read_text())
        if case == "a wrong type":
            saved["config"]["seed"] = "zero"
        if case == "an unknown key":
            saved["config"]["colour"] = 1
        (damaged / "config.json").write_text(text or json.dumps(saved))
        row(9, f"{case}: resume=", p.run("train", f"resume={damaged}", "total_steps=3200"))
        row(9, f"{case}: plot", p.run("plot", "curves", str(damaged), f"out={p.root / 'p9'}"))
    # 10: the latest checkpoint damaged.
    for case in ("truncated", "state removed", "meta cut"):
        broken = p.copy(finished, f"broken-{case.replace(' ', '-')}")
        latest = max((broken / "checkpoints").iterdir(), key=lambda x: int(x.name))
        if case == "truncated":
            for path in (latest / "state").rglob("*"):
                if path.is_file() and path.stat().st_size > 16:
                    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
        elif case == "state removed":
            shutil.rmtree(latest / "state")
        else:
            (latest / "meta" / "metadata").write_bytes(
                (latest / "meta" / "metadata").read_bytes()[:20]
            )
        row(10, f"{case}: resume=", p.run("train", f"resume={broken}", "total_steps=3200"))
    # 11: unwritable places.
    a_file = p.root / "a_file"
    a_file.write_text("mine")
    row(11, "out= an existing file", p.run("train", *TINY, f"out={a_file}"))
    row(11, "out= under /proc", p.run("train", *TINY, "out=/proc/solar_jax_probe"))
    row(
        11,
        "SOLAR_JAX_CACHE unwritable",
        p.run(
            "train",
            *TINY,
            "total_steps=100",
            f"out={p.root / 'c11'}",
            env={"SOLAR_JAX_CACHE": str(a_file / "cache")},
        ),
    )
    # 12: concurrent writers of compile_times.json.
    code = (
        "import multiprocessing as mp\n"
        "from solar_jax.xla.times import save_compile_time\n"
        "def w(i):\n"
        "    n = 0\n"
        "    for j in range(60):\n"
        "        try: save_compile_time(f'k{i}-{j}', 1.0)\n"
        "        except Exception: n += 1\n"
        "    return n\n"
        "if __name__ == '__main__':\n"
        "    with mp.Pool(4) as pool: failed = sum(pool.map(w, range(4)))\n"
        "    print(failed, 'of 240 writes failed', file=__import__('sys').stderr)\n"
    )
    row(12, "4 processes x 60 writes", p.python(code))
    # 13: a video of a run whose replay grew (the policy's restore, without rendering).
    restore = "from solar_jax.viz.video import restore; "
    restore += f"print(restore({str(finished)!r})[1].replay.capacity)"
    row(13, "restore for a video", p.python(restore))
    # 14: a crafted sweep.json.
    victim = p.root / "victim"
    victim.mkdir()
    (victim / "metrics.jsonl").write_text("precious\n")
    crafted = p.root / "crafted"
    outcome = p.run("sweep", *TINY, "seeds=1", "total_steps=100", f"out={crafted}")
    saved = json.loads((crafted / "sweep.json").read_text())
    saved["seeds"] = ["/../../victim"]
    (crafted / "sweep.json").write_text(json.dumps(saved))
    outcome = p.run("sweep", f"resume={crafted}", "total_steps=200")
    intact = (victim / "metrics.jsonl").exists() and sorted(x.name for x in victim.iterdir()) == [
        "metrics.jsonl"
    ]
    row(14, "seeds ['/../../victim'], resume=", outcome, f"victim untouched: {intact}")
    # 15: a program file replaced by a pickle that runs code.
    marker = p.root / "code_ran"
    payload = (
        "import pickle, pathlib, sys\n"
        "class P:\n"
        f"    def __reduce__(self): return (pathlib.Path.touch, (pathlib.Path({str(marker)!r}),))\n"
        "for f in pathlib.Path(sys.argv[1]).iterdir(): f.write_bytes(pickle.dumps((P(), None)))\n"
    )
    subprocess.run([sys.executable, "-c", payload, str(p.root / "cache" / "programs")], check=True)
    outcome = p.run("train", *TINY, "total_steps=100", f"out={p.root / 'r15'}")
    row(15, "programs/ replaced by pickles", outcome, f"code ran: {marker.exists()}")
    return rows


def main(argv: list[str] | None = None) -> int:
    options = parse_options(sys.argv[1:] if argv is None else argv, OPTIONS, __doc__)
    repo = Path(options["repo"]).resolve()
    with tempfile.TemporaryDirectory(prefix="fault_probe_") as scratch:
        rows = probes(Probe(repo, Path(scratch), float(options["timeout"])))
    commit = subprocess.run(
        ["git", "-C", str(repo), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    print("\nfault | case | exit | traceback | last stderr line | files")
    for r in rows:
        exit_code = "hang" if r["hang"] else r["rc"]
        cells = [r["fault"], r["case"], exit_code, r["traceback"], r["line"], r["files"]]
        print(" | ".join(map(str, cells)))
    out = Path(options["out"]) if options["out"] else RESULTS
    out.mkdir(parents=True, exist_ok=True)
    name = "fault_probe" + (f"_{options['tag']}" if options["tag"] else "") + ".json"
    result = {"commit": commit, "timeout_s": float(options["timeout"]), "rows": rows}
    (out / name).write_text(json.dumps(result, indent=1))
    print(f"-> {out / name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
