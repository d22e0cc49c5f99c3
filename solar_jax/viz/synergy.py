"""Synergies on the robots (as the SOLAR paper draws them) and their number over training.

A drawing is the robot in the x–z plane (the robots are planar) at its initial pose
``qpos0``, from its own kinematics; each agent's joint is a marker coloured by its
synergy, exemplars as triangles (markers of joints that coincide, as left and right
limbs do in the plane, are set side by side). Labels come from a round record's
``synergy/<name>/labels`` (one per real agent, agent i = MuJoCo body i + 1).
"""

import dataclasses
import math
from collections.abc import Sequence
from pathlib import Path

import mujoco
import numpy as np
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Polygon
from matplotlib.ticker import MaxNLocator

from solar_jax.morphology import Morphology
from solar_jax.viz.figures import colour, new_figure, save
from solar_jax.viz.runs import Run, VizError, group_runs, run_names, suite_name
from solar_jax.viz.stats import on_grid

_XZ = [0, 2]
_BODY = "0.75"  # light grey
_COLUMNS = 4


@dataclasses.dataclass(frozen=True)
class RobotGeometry:
    """One robot at ``qpos0`` projected on the x–z plane."""

    capsules: np.ndarray  # [C, 2, 2] axis end points (x, z); cylinders alike
    capsule_radii: np.ndarray  # [C]
    spheres: np.ndarray  # [S, 3] (x, z, radius)
    joints: np.ndarray  # [N, 2] each agent's hinge anchor; the torso: its body position


def robot_geometry(morph: Morphology) -> RobotGeometry:
    """The geoms and joint anchors of ``morph`` after ``mj_forward`` at ``qpos0``."""
    model = morph.model
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    capsules, radii, spheres = [], [], []
    for g in range(model.ngeom):
        kind = int(model.geom_type[g])  # numpy ints are never `in` a tuple of enums
        centre, radius = data.geom_xpos[g], model.geom_size[g, 0]
        if kind in (mujoco.mjtGeom.mjGEOM_CAPSULE, mujoco.mjtGeom.mjGEOM_CYLINDER):
            half = data.geom_xmat[g].reshape(3, 3)[:, 2] * model.geom_size[g, 1]
            capsules.append([(centre - half)[_XZ], (centre + half)[_XZ]])
            radii.append(radius)
        elif kind == mujoco.mjtGeom.mjGEOM_SPHERE:
            spheres.append([centre[0], centre[2], radius])
    joints = [data.xpos[1][_XZ]]
    joints += [data.xanchor[model.joint(name).id][_XZ] for name in morph.joints[1:]]
    return RobotGeometry(
        capsules=np.reshape(capsules, (-1, 2, 2)),
        capsule_radii=np.asarray(radii),
        spheres=np.reshape(spheres, (-1, 3)),
        joints=np.asarray(joints),
    )


def synergy_record(run: Run, round_: int | None = None) -> dict:
    """The round record whose clustering to draw: round ``round_``, default the last."""
    key = f"synergy/{run.names[0]}/labels"
    rounds = [r for r in run.records_of("round") if key in r]
    if not rounds:
        if run.records_of("round"):
            raise VizError(
                f"{run.path}: method {run.method} has no synergies (only solar and "
                "solar_no_pref cluster agents)"
            )
        raise VizError(f"{run.path}: no training round logged yet, so no synergies")
    if round_ is None:
        return rounds[-1]
    for record in rounds:
        if record["round"] == round_:
            return record
    raise VizError(
        f"{run.path}: no round {round_}; rounds {rounds[0]['round']} to {rounds[-1]['round']}"
    )


def _bounds(geometry: RobotGeometry) -> tuple[np.ndarray, np.ndarray]:
    """(min, max) over x and z of the robot's geoms, its joints and the floor (z = 0)."""
    r = geometry.capsule_radii[:, None, None]
    points = [
        (geometry.capsules - r).reshape(-1, 2),
        (geometry.capsules + r).reshape(-1, 2),
        geometry.spheres[:, :2] - geometry.spheres[:, 2:],
        geometry.spheres[:, :2] + geometry.spheres[:, 2:],
        geometry.joints,
        geometry.joints[:1] * [1.0, 0.0],  # the floor under the torso
    ]
    points = np.concatenate(points)
    return points.min(axis=0), points.max(axis=0)


def _draw_body(ax, geometry: RobotGeometry) -> None:
    for (start, end), radius in zip(geometry.capsules, geometry.capsule_radii, strict=True):
        axis = end - start
        normal = np.array([-axis[1], axis[0]]) / max(np.linalg.norm(axis), 1e-12) * radius
        corners = [start + normal, end + normal, end - normal, start - normal]
        ax.add_patch(Polygon(corners, color=_BODY, linewidth=0))
        for point in (start, end):
            ax.add_patch(Circle(point, radius, color=_BODY, linewidth=0))
    for x, z, radius in geometry.spheres:
        ax.add_patch(Circle((x, z), radius, color=_BODY, linewidth=0))


def marker_positions(joints: np.ndarray, spacing: float) -> np.ndarray:
    """``joints`` ``[N, 2]`` with coincident ones moved apart by ``spacing`` along x, in
    agent order: a planar robot's left and right limbs lie on top of each other at
    ``qpos0``, and both of their synergies must show."""
    positions = np.array(joints, dtype=np.float64)
    for agent in range(1, len(positions)):
        same = np.linalg.norm(joints[:agent] - joints[agent], axis=1) < 1e-6
        positions[agent, 0] += spacing * np.count_nonzero(same)
    return positions


def _draw_robot(ax, geometry: RobotGeometry, labels, exemplars, num_colours: int) -> None:
    _draw_body(ax, geometry)
    low, high = _bounds(geometry)
    size = np.max(high - low)
    for agent, (x, z) in enumerate(marker_positions(geometry.joints, 0.06 * size)):
        ax.scatter(
            x,
            z,
            s=70,
            marker="^" if agent in exemplars else "o",
            color=colour(labels[agent], num_colours),
            edgecolors="black",
            linewidths=0.8,
            zorder=3,
        )
    ax.axhline(0.0, color="0.4", linewidth=0.8)  # the floor
    centre, half = (low + high) / 2, 0.6 * size  # a square view with a margin
    ax.set(xlim=(centre[0] - half, centre[0] + half), ylim=(centre[1] - half, centre[1] + half))
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])


def draw_synergies(
    run: Run,
    out_dir: str | Path,
    round_: int | None = None,
    name: str | None = None,
    stem: str | None = None,
) -> list[Path]:
    """Every morphology of ``run``'s suite with its synergies at round ``round_`` (default
    the last), in one grid. Writes ``<stem>.png`` and ``.svg`` (default stem
    ``synergy-<name>-round<r>``)."""
    record = synergy_record(run, round_)
    name = name or run.path.resolve().name
    count = len(run.names)
    cols = min(_COLUMNS, count)
    fig, axes = new_figure(math.ceil(count / cols), cols, (3.2, 3.2))
    for ax in axes.flat[count:]:
        ax.axis("off")
    num_colours = max(max(record[f"synergy/{m}/labels"]) + 1 for m in run.names)
    for ax, morph in zip(axes.flat, run.names, strict=False):
        labels = record[f"synergy/{morph}/labels"]
        exemplars = record[f"synergy/{morph}/exemplars"]
        _draw_robot(ax, robot_geometry(run.morphology(morph)), labels, exemplars, num_colours)
        held = " (held out)" if morph in run.held_out else ""
        clusters = record[f"synergy/{morph}/num_clusters"]
        ax.set_title(f"{suite_name(morph)}{held}\n{clusters} synergies", fontsize="medium")
    markers = [
        Line2D([], [], marker="^", color="0.5", linestyle="", label="exemplar"),
        Line2D([], [], marker="o", color="0.5", linestyle="", label="joint (colour: synergy)"),
    ]
    fig.legend(handles=markers, loc="outside lower center", ncols=2, fontsize="small")
    fig.suptitle(
        f"{suite_name(run.suite)} synergies, {run.method}\n{name}\n"
        f"round {record['round']} ({record['env_steps']:,} env steps)",
        fontsize="medium",  # a one-robot figure is 3.2 inches wide: the run's name fits
    )
    return save(fig, out_dir, stem or f"synergy-{name}-round{record['round']}")


def draw_all_synergies(
    runs: Sequence[Run], out_dir: str | Path, round_: int | None = None
) -> list[Path]:
    """``draw_synergies`` for each run (names made unique among them)."""
    paths = []
    for run, name in zip(runs, run_names(runs), strict=True):
        paths += draw_synergies(run, out_dir, round_, name)
    return paths


def cluster_curve(run: Run, morph: str) -> tuple[np.ndarray, np.ndarray]:
    """(env steps, number of synergies) of ``morph`` over ``run``'s rounds."""
    key = f"synergy/{morph}/num_clusters"
    records = [r for r in run.records_of("round") if key in r]
    steps = np.array([r["env_steps"] for r in records], dtype=np.float64)
    return steps, np.array([r[key] for r in records], dtype=np.float64)


def plot_clusters(runs: Sequence[Run], out_dir: str | Path) -> list[Path]:
    """Number of synergies against env steps: one panel per (suite, method and varying
    config), one line per morphology (held-out ones dashed), the mean over the panel's
    seeds on a common grid. Runs without synergies are left out. Writes
    ``clusters.png`` and ``.svg``."""
    clustered = [run for run in runs if run.has_synergies]
    if not clustered:
        methods = ", ".join(sorted({run.method for run in runs}))
        raise VizError(f"no run has synergies (methods: {methods}; only solar and solar_no_pref)")
    groups = group_runs(clustered)
    fig, axes = new_figure(len(groups), 1, (7.5, 3.5))
    for ax, ((suite, label), members) in zip(axes[:, 0], groups.items(), strict=True):
        names = members[0].names
        for i, morph in enumerate(names):
            grid, values = on_grid([cluster_curve(run, morph) for run in members])
            held = morph in members[0].held_out
            ax.plot(
                grid,
                values.mean(axis=0),
                color=colour(i, len(names)),
                linestyle="--" if held else "-",
                label=morph + (" (held out)" if held else ""),
            )
        seeds = f"mean of {len(members)} runs" if len(members) > 1 else "1 run"
        ax.set_ylim(bottom=0)  # counts: integer ticks from 0
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set(
            title=f"{suite_name(suite)}: {label} ({seeds})",
            xlabel="env steps",
            ylabel="synergies",
        )
        ax.grid(alpha=0.3)
        ax.legend(fontsize="x-small", loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return save(fig, out_dir, "clusters")
