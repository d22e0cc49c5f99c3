"""Field-by-field comparison of two compiled MuJoCo models (test helper).

The quantities that make two planar robots physically the same robot: the body tree,
inertial properties, geoms and contact parameters, joints, dofs, actuators, options
and the initial configuration.
"""

import mujoco
import numpy as np

# (group, MjModel attribute). Quaternions are compared up to sign.
COMPARED_FIELDS = (
    ("body tree", "body_parentid"),
    ("body tree", "body_jntnum"),
    ("body tree", "body_geomnum"),
    ("body frames", "body_pos"),
    ("body frames", "body_quat"),
    ("inertia", "body_mass"),
    ("inertia", "body_inertia"),
    ("inertia", "body_ipos"),
    ("inertia", "body_iquat"),
    ("geoms", "geom_bodyid"),
    ("geoms", "geom_type"),
    ("geoms", "geom_size"),
    ("geoms", "geom_pos"),
    ("geoms", "geom_quat"),
    ("contact", "geom_friction"),
    ("contact", "geom_condim"),
    ("contact", "geom_contype"),
    ("contact", "geom_conaffinity"),
    ("contact", "geom_solref"),
    ("contact", "geom_solimp"),
    ("contact", "geom_solmix"),
    ("contact", "geom_margin"),
    ("contact", "geom_gap"),
    ("contact", "geom_priority"),
    ("joints", "jnt_type"),
    ("joints", "jnt_bodyid"),
    ("joints", "jnt_axis"),
    ("joints", "jnt_pos"),
    ("joints", "jnt_limited"),
    ("joints", "jnt_range"),
    ("joints", "jnt_solref"),
    ("joints", "jnt_solimp"),
    ("joints", "jnt_stiffness"),
    ("joints", "jnt_margin"),
    ("dofs", "dof_armature"),
    ("dofs", "dof_damping"),
    ("dofs", "dof_frictionloss"),
    ("actuators", "actuator_trntype"),
    ("actuators", "actuator_trnid"),
    ("actuators", "actuator_gear"),
    ("actuators", "actuator_ctrllimited"),
    ("actuators", "actuator_ctrlrange"),
    ("actuators", "actuator_forcelimited"),
    ("actuators", "actuator_gaintype"),
    ("actuators", "actuator_gainprm"),
    ("actuators", "actuator_biastype"),
    ("actuators", "actuator_biasprm"),
    ("actuators", "actuator_dyntype"),
    ("initial state", "qpos0"),
    ("initial state", "qpos_spring"),
)
OPTION_FIELDS = (
    "timestep",
    "integrator",
    "gravity",
    "cone",
    "solver",
    "iterations",
    "ls_iterations",
    "tolerance",
    "impratio",
    "jacobian",
    "disableflags",
)


def _field(model: mujoco.MjModel, name: str) -> np.ndarray:
    return np.asarray(getattr(model, name), dtype=np.float64)


def field_errors(ours: mujoco.MjModel, reference: mujoco.MjModel) -> dict[str, float]:
    """Max absolute difference per compared field (inf on a shape mismatch)."""
    errors = {}
    for _, name in COMPARED_FIELDS:
        a, b = _field(ours, name), _field(reference, name)
        if a.shape != b.shape:
            errors[name] = float("inf")
            continue
        if name.endswith("quat"):
            diff = np.minimum(np.abs(a - b).max(-1), np.abs(a + b).max(-1))
        else:
            diff = np.abs(a - b)
        errors[name] = float(diff.max()) if diff.size else 0.0
    for name in OPTION_FIELDS:
        a = np.asarray(getattr(ours.opt, name), np.float64)
        b = np.asarray(getattr(reference.opt, name), np.float64)
        errors[f"opt.{name}"] = float(np.abs(a - b).max())
    return errors


def world_pose_error(ours: mujoco.MjModel, reference: mujoco.MjModel) -> float:
    """Max difference of body world positions and geom world positions at qpos0."""
    out = []
    for model in (ours, reference):
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        out.append(np.concatenate([data.xpos.ravel(), data.geom_xpos.ravel(), data.xipos.ravel()]))
    return float(np.abs(out[0] - out[1]).max())
