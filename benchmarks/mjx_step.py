"""A vmapped MJX step under the installed jax, per XLA:CPU setting: does this jax run
batched MJX as fast as the pinned one, and which flag makes it so?

    python benchmarks/mjx_step.py [robot=walker_7_main] [batch=1024] [steps=10]
                                  [repeats=3] [timeout=300]

Each setting runs in a child process (XLA reads its flags once, at backend start):
``package`` (what importing solar_jax sets), ``ynn_default`` (that less the package's
YNNPACK setting: XLA's own choice of YNNPACK fusions) and ``ynn_none`` (no YNNPACK
fusions). The child jits ``steps`` MJX
steps of ``batch`` worlds of ``robot`` (``mjx.step`` vmapped, in a ``fori_loop``),
compiles, then reports the best of ``repeats`` timed calls and a hash of the final
``qpos``/``qvel`` (equal hashes: the same bits). A child that exceeds ``timeout``
seconds (the deadlock jaxlib 0.10.0 showed at batch 1,024 on 2 cores) is reported as
such. Prints a table and writes ``benchmarks/results/mjx_step_<jax version>_<device>.json``.
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

RESULTS = Path(__file__).resolve().parent / "results"
YNN = "--xla_cpu_experimental_ynn_fusion_type"
SETTINGS = ("package", "ynn_default", "ynn_none")
DEFAULTS = dict(robot="walker_7_main", batch=1024, steps=10, repeats=3, timeout=300)


def child(setting: str, robot: str, batch: int, steps: int, repeats: int) -> dict:
    """Times the vmapped step in this process under ``setting`` (module docstring)."""
    import solar_jax  # noqa: F401  (before jax: the package's XLA flags)

    flags = [f for f in os.environ.get("XLA_FLAGS", "").split() if not f.startswith(YNN)]
    if setting != "package":  # before jax's backend starts, which reads XLA_FLAGS once
        os.environ["XLA_FLAGS"] = " ".join(flags + ([f"{YNN}="] if setting == "ynn_none" else []))

    import jax
    import numpy as np
    from mujoco import mjx

    from solar_jax.morphology import load

    model = mjx.put_model(load(robot).model)
    data = mjx.make_data(model)
    keys = jax.random.split(jax.random.key(0), batch)
    worlds = jax.vmap(lambda k: data.replace(qvel=0.1 * jax.random.normal(k, data.qvel.shape)))(
        keys
    )
    step = jax.vmap(lambda d: mjx.step(model, d))
    run = jax.jit(lambda w: jax.lax.fori_loop(0, steps, lambda _, w: step(w), w))
    start = time.perf_counter()
    compiled = run.lower(worlds).compile()
    compile_s = time.perf_counter() - start
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        out = jax.block_until_ready(compiled(worlds))
        times.append(time.perf_counter() - start)
    digest = hashlib.sha1(np.asarray(out.qpos).tobytes() + np.asarray(out.qvel).tobytes())
    return dict(
        compile_s=compile_s,
        best_s=min(times),
        steps_per_s=steps * batch / min(times),
        hash=digest.hexdigest()[:12],
        xla_flags=os.environ.get("XLA_FLAGS", ""),
    )


def main(argv: list[str]) -> int:
    if {"-h", "--help"} & set(argv):
        print(__doc__)
        return 0
    options = dict(DEFAULTS, setting="")
    for arg in argv:
        key, _, value = arg.partition("=")
        if key not in options or not value:
            raise SystemExit(f"mjx_step: unknown or empty option {arg!r} (keys: {list(DEFAULTS)})")
        if key in ("robot", "setting"):
            options[key] = value
        elif not value.isdigit() or int(value) < 1:
            raise SystemExit(f"mjx_step: {key} must be a positive integer, got {value!r}")
        else:
            options[key] = int(value)
    keys = ("robot", "batch", "steps", "repeats")
    if options["setting"] in SETTINGS:  # a child
        print(json.dumps(child(options["setting"], **{k: options[k] for k in keys})))
        return 0
    from importlib import metadata

    import jax

    from solar_jax.morphology import load

    try:
        load(options["robot"])
    except (ValueError, OSError) as error:  # an unknown name, a missing or bad file
        raise SystemExit(f"mjx_step: robot: {error}") from None

    rows = []
    for name in SETTINGS:
        args = [f"{k}={options[k]}" for k in keys]
        command = [sys.executable, str(Path(__file__).resolve()), *args, f"setting={name}"]
        try:
            done = subprocess.run(
                command, capture_output=True, text=True, timeout=options["timeout"]
            )
            lines = done.stdout.strip().splitlines()
            row = json.loads(lines[-1]) if done.returncode == 0 else {"error": done.stderr[-300:]}
        except subprocess.TimeoutExpired:
            row = {"error": f"no result within {options['timeout']} s (hung?)"}
        rows.append({"setting": name, **row})
        print(f"{name}: {json.dumps(rows[-1])}", flush=True)
    version = metadata.version("jaxlib")
    device = jax.devices()[0].platform
    print(
        f"\n{options['robot']}, {options['batch']} worlds x {options['steps']} steps, "
        f"jaxlib {version}, {device}"
    )
    print("| setting | compile s | physics steps/s | hash |\n|---|---:|---:|---|")
    for row in rows:
        if "error" in row:
            print(f"| {row['setting']} | - | {(row['error'].splitlines() or ['failed'])[-1]} | - |")
        else:
            print(
                f"| {row['setting']} | {row['compile_s']:.1f} | {row['steps_per_s']:,.0f} | "
                f"{row['hash']} |"
            )
    del options["setting"]
    meta = dict(options=options, jaxlib=version, device=device, machine=platform.machine())
    out = RESULTS / f"mjx_step_{version}_{device}.json"
    out.write_text(json.dumps({"meta": meta, "rows": rows}, indent=2))
    print(f"-> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
