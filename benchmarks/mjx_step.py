"""A vmapped MJX step under the installed jax, per XLA:CPU setting and MJX implementation:
does this jax run batched MJX as fast as the pinned one, which flag makes it so, and what
MJX's Warp implementation costs to start and to step beside its JAX one.

    python benchmarks/mjx_step.py [robot=walker_7_main] [batch=1024] [steps=10]
                                  [repeats=3] [timeout=300] [impls=jax,warp] [tag=NAME]

Each row runs in a child process (XLA reads its flags once, at backend start). JAX
implementation: ``package`` (what importing solar_jax sets), ``ynn_default`` (that less
the package's YNNPACK setting: XLA's own choice of YNNPACK fusions) and ``ynn_none`` (no
YNNPACK fusions). Warp implementation (``mjx.put_model(..., impl="warp")``, needs
warp-lang; its kernels are cached on disk, so a second run starts warm): ``package``. The
child jits ``steps`` MJX steps of ``batch`` worlds of ``robot`` (``mjx.step`` vmapped, in
a ``fori_loop``) from qvel ~ N(0, 0.1), then reports the first call's seconds (tracing,
compiling, kernel builds, one run), the best of ``repeats`` timed calls, the largest
|qpos| difference from MuJoCo C's ``mj_step`` over the first 16 worlds, and a hash of the
final ``qpos``/``qvel`` (equal hashes: the same bits). A child that exceeds ``timeout``
seconds (the deadlock jaxlib 0.10.0 showed at batch 1,024 on 2 cores) is reported as
such. Prints a table and writes
``benchmarks/results/mjx_step_<robot>_<jaxlib version>_b<batch>[_<tag>]_<device>.json``.
"""

import hashlib
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.options import parse_options  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
YNN = "--xla_cpu_experimental_ynn_fusion_type"
SETTINGS = {"jax": ("package", "ynn_default", "ynn_none"), "warp": ("package",)}
OPTIONS = {
    "robot": "walker_7_main",
    "batch": "1024",
    "steps": "10",
    "repeats": "3",
    "timeout": "300",
    "impls": "jax",  # jax,warp adds the Warp row (it needs warp-lang)
    "tag": "",
}
COUNTS = ("batch", "steps", "repeats", "timeout")  # options that are positive integers
CHECKED_WORLDS = 16  # worlds compared with MuJoCo C


def child(setting: str, impl: str, robot: str, batch: int, steps: int, repeats: int) -> dict:
    """Times the vmapped step in this process under ``setting`` (module docstring)."""
    import solar_jax  # noqa: F401  (before jax: the package's XLA flags)

    flags = [f for f in os.environ.get("XLA_FLAGS", "").split() if not f.startswith(YNN)]
    if setting != "package":  # before jax's backend starts, which reads XLA_FLAGS once
        os.environ["XLA_FLAGS"] = " ".join(flags + ([f"{YNN}="] if setting == "ynn_none" else []))

    import jax
    import mujoco
    import numpy as np
    from mujoco import mjx

    from solar_jax.morphology import load

    m = load(robot).model
    qvel = 0.1 * np.random.default_rng(0).standard_normal((batch, m.nv)).astype(np.float32)
    start = time.perf_counter()
    if impl == "warp":
        model = mjx.put_model(m, impl="warp", device=jax.devices()[0])
        template = mjx.make_data(m, impl="warp", naconmax=1_000, njmax=200)
    else:
        model = mjx.put_model(m)
        template = mjx.make_data(model)
    worlds = jax.vmap(lambda v: template.replace(qvel=v))(jax.numpy.asarray(qvel))
    step = jax.vmap(mjx.step, in_axes=(None, 0))
    run = jax.jit(lambda w: jax.lax.fori_loop(0, steps, lambda _, w: step(model, w), w))
    out = jax.block_until_ready(run(worlds))
    first_s = time.perf_counter() - start
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        out = jax.block_until_ready(run(worlds))
        times.append(time.perf_counter() - start)
    error = 0.0
    for w in range(min(batch, CHECKED_WORLDS)):
        d = mujoco.MjData(m)
        d.qvel[:] = qvel[w]
        mujoco.mj_step(m, d, steps)
        error = max(error, float(np.abs(np.asarray(out.qpos[w]) - d.qpos).max()))
    digest = hashlib.sha1(np.asarray(out.qpos).tobytes() + np.asarray(out.qvel).tobytes())
    return dict(
        first_call_s=first_s,
        best_s=min(times),
        steps_per_s=steps * batch / min(times),
        qpos_error_vs_c=error,
        hash=digest.hexdigest()[:12],
        xla_flags=os.environ.get("XLA_FLAGS", ""),
    )


def main(argv: list[str]) -> int:
    if argv[:1] == ["--child"]:  # impl, setting, robot, batch, steps, repeats
        impl, setting, robot, *counts = argv[1:]
        print("ROW " + json.dumps(child(setting, impl, robot, *map(int, counts))), flush=True)
        return 0
    options = parse_options(argv, OPTIONS, __doc__)
    for key in COUNTS:
        if not options[key].isdigit() or int(options[key]) < 1:
            raise SystemExit(f"mjx_step: {key} must be a positive integer, got {options[key]!r}")
    impls = options["impls"].split(",")
    if not set(impls) <= set(SETTINGS):
        raise SystemExit(f"mjx_step: impls must name jax and/or warp, got {options['impls']!r}")
    from importlib import metadata
    from importlib.util import find_spec

    import jax

    from solar_jax.morphology import load

    try:
        load(options["robot"])
    except (ValueError, OSError) as error:  # an unknown name, a missing or bad file
        raise SystemExit(f"mjx_step: robot: {error}") from None

    rows = []
    counts = [options[k] for k in ("batch", "steps", "repeats")]
    for impl in impls:
        for name in SETTINGS[impl]:
            command = [sys.executable, __file__, "--child", impl, name, options["robot"], *counts]
            if impl == "warp" and find_spec("warp") is None:
                row = {"error": "warp-lang is not installed (mujoco-mjx's warp extra)"}
            else:
                row = _run_child(command, int(options["timeout"]))
            rows.append({"impl": impl, "setting": name, **row})
            print(f"{impl} {name}: {json.dumps(rows[-1])}", flush=True)
    version = metadata.version("jaxlib")
    device = jax.devices()[0].platform
    print(
        f"\n{options['robot']}, {options['batch']} worlds x {options['steps']} steps, "
        f"jaxlib {version}, {device}"
    )
    print("| impl | setting | first call s | physics steps/s | max abs qpos error vs C | hash |")
    print("|---|---|---:|---:|---:|---|")
    for row in rows:
        head = f"| {row['impl']} | {row['setting']} |"
        if "error" in row:
            print(f"{head} - | {(row['error'].splitlines() or ['failed'])[-1]} | - | - |")
        else:
            print(
                f"{head} {row['first_call_s']:.1f} | {row['steps_per_s']:,.0f} | "
                f"{row['qpos_error_vs_c']:.1e} | {row['hash']} |"
            )
    meta = dict(options=options, jaxlib=version, device=device, machine=platform.machine())
    tag = f"_{options['tag']}" if options["tag"] else ""
    out = RESULTS / f"mjx_step_{options['robot']}_{version}_b{options['batch']}{tag}_{device}.json"
    out.write_text(json.dumps({"meta": meta, "rows": rows}, indent=2))
    print(f"-> {out}")
    return 0


def _run_child(command: list[str], timeout: int) -> dict:
    """A child's row, or its error (the last of its stderr, or that it hung)."""
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"error": f"no result within {timeout} s (hung?)"}
    rows = [json.loads(line[4:]) for line in done.stdout.splitlines() if line[:4] == "ROW "]
    if done.returncode != 0 or not rows:
        return {"error": done.stderr[-300:] or f"exit {done.returncode}"}
    return rows[-1]


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
