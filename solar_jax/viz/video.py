"""A rollout video of a run's latest checkpoint: the deterministic policy on one robot.

The rollout is the single-robot MJX env (``solar_jax.env.single``) under one jitted
``lax.scan``, its observations padded to the trainer's N_max so the suite's networks
act on them; it stops at the first episode end. Frames are rendered from the qpos
sequence by MuJoCo's renderer on the host. MuJoCo picks its OpenGL backend from
``MUJOCO_GL`` when it is imported (``python -m solar_jax.plot`` defaults it to egl).
"""

import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from PIL import Image

from solar_jax.env.single import Env, make_env
from solar_jax.morphology import Morphology
from solar_jax.training.checkpoint import CheckpointError
from solar_jax.training.policy import restore_policy
from solar_jax.training.trainer import Trainer, TrainerState
from solar_jax.viz.gl import open_renderer
from solar_jax.viz.runs import VizError, load_run
from solar_jax.xla.options import jit_physics

TARGET_FPS = 30.0
"""Frames are every k-th env step, k chosen for about this rate (played in real time)."""


def restore(run_dir: str | Path, checkpoint: str = "latest") -> tuple[Trainer, TrainerState, int]:
    """``training.policy.restore_policy``, its errors as ``VizError``."""
    try:
        return restore_policy(run_dir, checkpoint)
    except CheckpointError as err:
        raise VizError(str(err)) from None


def rollout(trainer: Trainer, state: TrainerState, env: Env, index: int, steps: int) -> np.ndarray:
    """qpos ``[T, nq]`` of the deterministic policy on ``env``, the trainer's morphology
    ``index``: the reset state, then every step up to the first episode end
    (``T <= steps + 1``; the end's own state is not shown, the env has reset it)."""
    n, n_max = env.num_agents, trainer.env.n_max
    mask, traversal = trainer.agent_mask[index], trainer.traversal[index]
    tree = jax.tree.map(lambda x: x[index], trainer.tree)  # read by SMP only

    # Parameters are arguments, not constants: one program per suite and config, which the
    # persistent compilation cache then serves for every checkpoint.
    def run(actor, synergy, key: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
        def policy(obs: jax.Array) -> jax.Array:
            padded = jnp.zeros((n_max, obs.shape[-1]), obs.dtype).at[:n].set(obs)
            action = trainer.networks.act(actor, padded[None], mask, synergy, traversal, tree)
            return jnp.clip(action[0, 1:n], -1.0, 1.0)  # agent 0 is the torso: no actuator

        def step(env_state, _):
            env_state = env.step(env_state, policy(env_state.obs))
            return env_state, (env_state.qpos, env_state.done)

        first = env.reset(key)
        _, (qpos, done) = jax.lax.scan(step, first, length=steps)
        return first.qpos, qpos, done

    synergy = jax.tree.map(lambda x: x[index], state.synergy)
    key = jax.random.PRNGKey(trainer.config.seed)
    first, qpos, done = jax.device_get(jit_physics(run)(state.agent.actor, synergy, key))
    end = int(np.argmax(done)) if done.any() else steps
    return np.concatenate([first[None], qpos[:end]])


def _camera(model: mujoco.MjModel, data: mujoco.MjData) -> mujoco.MjvCamera:
    """A side view (looking along +y at the x–z plane) that tracks the robot, at a
    distance from its initial torso height (the model's extent counts the floor)."""
    mujoco.mj_kinematics(model, data)
    camera = mujoco.MjvCamera()
    camera.type = mujoco.mjtCamera.mjCAMERA_TRACKING
    camera.trackbodyid = 1
    camera.distance = 3.0 * max(float(data.xpos[1, 2]), 0.5)
    camera.azimuth = 90.0
    camera.elevation = -10.0
    return camera


def render(
    morph: Morphology, qpos: np.ndarray, width: int, height: int, stride: int = 1
) -> list[np.ndarray]:
    """RGB frames ``[height, width, 3]`` of every ``stride``-th qpos."""
    renderer = open_renderer(morph.textured_model(), width, height)  # skybox, floor grid
    model = renderer.model
    data = mujoco.MjData(model)
    camera = _camera(model, data)
    frames = []
    try:
        for q in qpos[::stride]:
            data.qpos[:] = q
            mujoco.mj_forward(model, data)
            renderer.update_scene(data, camera)
            frames.append(renderer.render().copy())
    finally:
        renderer.close()
    return frames


def _mp4_writer():
    """imageio's v2 API (its ffmpeg writer), or a ``VizError`` saying what to install."""
    try:
        import imageio.v2 as imageio
        import imageio_ffmpeg  # noqa: F401  (the ffmpeg binary imageio writes MP4 with)
    except ImportError:
        raise VizError(
            "MP4 needs imageio and imageio-ffmpeg (pip install 'solar_jax[video]'); or write a .gif"
        ) from None
    return imageio


def _check_out(out: str | Path | None) -> None:
    suffix = Path(out).suffix.lower() if out else ".gif"
    if suffix not in (".gif", ".mp4"):
        raise VizError(f"out={out}: expected a .gif or .mp4 file")
    if suffix == ".mp4":
        _mp4_writer()


def write_video(frames: list[np.ndarray], path: str | Path, fps: float) -> Path:
    """A GIF (Pillow) or an MP4 (imageio with imageio-ffmpeg)."""
    path = Path(path)
    _check_out(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".mp4":
        with warnings.catch_warnings():  # ffmpeg is fork-exec'd at once: JAX's threads are safe
            warnings.filterwarnings("ignore", "os.fork", RuntimeWarning)
            _mp4_writer().mimwrite(path, frames, fps=fps, macro_block_size=2)
    else:
        images = [Image.fromarray(frame) for frame in frames]
        duration = round(1000.0 / fps)
        images[0].save(path, save_all=True, append_images=images[1:], duration=duration, loop=0)
    return path


def rollout_video(
    run_dir: str | Path,
    out: str | Path | None = None,
    morph: str = "",
    steps: int = 1000,
    width: int = 480,
    height: int = 360,
    checkpoint: str = "latest",
) -> Path:
    """Renders the deterministic policy of ``checkpoint`` (latest, or best: ``restore``)
    on ``morph`` (default: the suite's first) for up to ``steps`` env steps or the first
    episode end. ``out``: a .gif or .mp4 file; default
    ``RUN_DIR/plots/video-<morph>-round<r>[-best].gif``.

    Everything that can fail cheaply (the output, the robot, OpenGL) is checked before
    the checkpoint is restored and the rollout compiled."""
    _check_out(out)
    run = load_run(run_dir)
    names = run.names
    name = morph or names[0]
    if name not in names:
        raise VizError(f"morph={name}: not in this run's suite; one of {', '.join(names)}")
    morphology = run.morphology(name)
    if out and Path(out).suffix.lower() == ".mp4":  # H.264 wants even sizes
        width, height = width + width % 2, height + height % 2
    open_renderer(morphology.model, width, height).close()
    trainer, state, round_ = restore(run_dir, checkpoint)
    env = make_env(morphology, trainer.config.env)
    qpos = rollout(trainer, state, env, names.index(name), steps)
    stride = max(1, round(1.0 / (morphology.dt * TARGET_FPS)))
    frames = render(morphology, qpos, width, height, stride)
    best = "-best" if checkpoint == "best" else ""
    out = out or Path(run_dir) / "plots" / f"video-{Path(name).stem}-round{round_}{best}.gif"
    return write_video(frames, out, 1.0 / (morphology.dt * stride))
