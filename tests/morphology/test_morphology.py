"""load(): the facts later layers need, for registered robots and user MJCF files."""

import numpy as np
import pytest

from solar_jax.morphology import ROBOTS, MorphologyError, Task, build_xml, load

# algorithm.md §3 fixtures: parents in pre-order.
REFERENCE_PARENTS = {
    "walker_7_main": (-1, 0, 1, 2, 0, 4, 5),
    "humanoid_2d_9_full": (-1, 0, 1, 0, 3, 0, 5, 0, 7),
    "hopper_4": (-1, 0, 1, 2),
    "walker_3_main": (-1, 0, 0),
    "humanoid_2d_8_left_knee": (-1, 0, 1, 0, 0, 4, 0, 6),
}


@pytest.mark.parametrize("name", list(REFERENCE_PARENTS))
def test_parents_match_spec_fixtures(name):
    assert load(name).parents == REFERENCE_PARENTS[name]


def test_walker_7_traversal_matches_spec_fixture():
    expected = [[0, 6, 6], [1, 2, 5], [2, 1, 1], [3, 0, 0], [4, 5, 4], [5, 4, 3], [6, 3, 2]]
    np.testing.assert_array_equal(load("walker_7_main").traversal, expected)


@pytest.mark.parametrize("name", list(ROBOTS))
def test_every_robot_has_consistent_facts(name):
    m = load(name)
    n = m.num_agents
    assert m.agents[0] == "torso" and m.num_actuators == n - 1
    # Actuator order is body pre-order (algorithm.md §1).
    np.testing.assert_array_equal(m.actuators, np.arange(-1, n - 1))
    for i in range(1, n):
        assert m.model.actuator_trnid[m.actuators[i], 0] == m.model.body_jntadr[i + 1]
        assert m.model.jnt_qposadr[m.model.body_jntadr[i + 1]] == m.qpos_adr[i]
    assert m.qpos_adr[0] == 2 and m.dof_adr[0] == 2  # the root pitch
    assert m.hop_distances.shape == (n, n) and m.traversal.shape == (n, 3)
    assert (m.joint_range[0] == 0).all() and (m.joint_range[1:, 0] < m.joint_range[1:, 1]).all()
    assert m.limb_types.shape == (n,) and m.limb_types.max() < 4


def test_limb_types_per_family():
    assert load("walker_7_main").limb_types.tolist() == [0, 1, 2, 3, 1, 2, 3]
    assert load("hopper_5").limb_types.tolist() == [0, 1, 2, 2, 3]
    assert load("cheetah_7_full").limb_types.tolist() == [0, 1, 2, 3, 1, 2, 3]
    humanoid = load("humanoid_2d_9_full")
    assert humanoid.limb_types.tolist() == [-1, 0, 1, 0, 1, 2, 3, 2, 3]
    # The reference's name-matching bug: every humanoid one-hot is zero (algorithm.md §2).
    assert humanoid.reference_limb_types.tolist() == [-1] * 9
    np.testing.assert_array_equal(load("walker_5_main").reference_limb_types, [0, 1, 2, 1, 2])


def test_joint_ranges_in_degrees():
    np.testing.assert_allclose(
        load("hopper_4").joint_range, [[0, 0], [-150, 0], [-150, 0], [-45, 45]], atol=1e-3
    )


def test_tasks_follow_spec_section_2():
    assert load("walker_2_main").task.z_range == (0.54, 1.74)
    assert load("walker_3_main").task.z_range == (0.54, 1.74)
    assert load("walker_4_main").task.z_range == (0.664, 1.864)
    for n in (5, 6, 7):
        assert load(f"walker_{n}_main").task.z_range == (0.8, 2.0)
    assert load("humanoid_2d_7_left_arm").task.z_range == (0.4, 2.1)
    for name, z in (("hopper_3", 0.45), ("hopper_4", 0.6), ("hopper_5", 0.95)):
        task = load(name).task
        assert task.z_range == (z, float("inf")) and task.max_abs_state == 100.0
        assert task.max_abs_pitch == 1.0
    cheetah = load("cheetah_4_back")
    assert not cheetah.task.terminates and cheetah.task.ctrl_cost == 0.1
    assert cheetah.task.alive_bonus == 0.0 and cheetah.task.reset_qvel_normal
    assert cheetah.dt == pytest.approx(0.04)
    walker = load("walker_7_main")
    assert walker.dt == pytest.approx(0.008)
    assert (walker.task.alive_bonus, walker.task.ctrl_cost) == (1.0, 1e-3)
    assert (walker.task.reset_qpos_noise, walker.task.reset_qvel_noise) == (0.005, 0.005)


def test_user_file_loads_like_the_registered_robot(tmp_path):
    path = tmp_path / "my_walker.xml"
    path.write_text(build_xml("walker_7_main"))
    ours, registered = load(path), load("walker_7_main")
    assert ours.name == "my_walker" and ours.family == "custom" and ours.source == str(path)
    assert ours.parents == registered.parents
    np.testing.assert_array_equal(ours.hop_distances, registered.hop_distances)
    np.testing.assert_array_equal(ours.traversal, registered.traversal)
    np.testing.assert_array_equal(ours.joint_range, registered.joint_range)
    # Depth-based limb types reproduce the walkers' name-based ones.
    np.testing.assert_array_equal(ours.limb_types, registered.limb_types)
    # Generic task: healthy above half the torso's initial height (qpos units: ref - h0/2).
    assert ours.task.z_range == pytest.approx((1.25 - 0.8, float("inf")))
    custom = Task(z_range=(0.1, 5.0))
    assert load(path, task=custom).task is custom


def test_user_file_with_actuators_out_of_preorder(tmp_path):
    xml = build_xml("walker_3_main")
    first = '<general name="left1_joint" joint="left1_joint" gear="100"/>'
    second = '<general name="right1_joint" joint="right1_joint" gear="100"/>'
    assert first in xml and second in xml
    swapped = xml.replace(first, "@").replace(second, first).replace("@", second)
    path = tmp_path / "swapped.xml"
    path.write_text(swapped)
    np.testing.assert_array_equal(load(path).actuators, [-1, 1, 0])


# ------------------------------------------------------------------- bad inputs

MINIMAL = """<mujoco>
  <worldbody>
    <body name="torso" pos="0 0 1">
      {root}
      <geom type="capsule" size="0.05" fromto="0 0 0 0 0 -0.4"/>
      <body name="leg" pos="0 0 -0.4">
        {leg_joints}
        <geom type="capsule" size="0.04" fromto="0 0 0 0 0 -0.4"/>
      </body>
    </body>
  </worldbody>
  <actuator>{motors}</actuator>
</mujoco>"""
ROOT = (
    '<joint name="rootx" type="slide" axis="1 0 0"/>'
    '<joint name="rootz" type="slide" axis="0 0 1"/>'
    '<joint name="rooty" type="hinge" axis="0 1 0"/>'
)
HINGE = '<joint name="hip" type="hinge" axis="0 -1 0" range="-60 60"/>'
MOTOR = '<motor joint="hip" gear="50"/>'


def _write(tmp_path, root=ROOT, leg_joints=HINGE, motors=MOTOR, text=None):
    path = tmp_path / "robot.xml"
    path.write_text(text or MINIMAL.format(root=root, leg_joints=leg_joints, motors=motors))
    return path


def test_minimal_user_robot_loads(tmp_path):
    m = load(_write(tmp_path))
    assert m.parents == (-1, 0) and m.num_actuators == 1
    np.testing.assert_allclose(m.joint_range[1], [-60, 60], atol=1e-9)


@pytest.mark.parametrize(
    ("kwargs", "problem"),
    [
        (
            {"leg_joints": HINGE + '<joint name="knee" axis="0 1 0" range="-1 1"/>'},
            "body 'leg' has 2 joints",
        ),
        ({"leg_joints": "", "motors": ""}, "body 'leg' has 0 joints"),
        ({"motors": ""}, "joint 'hip' has no motor"),
        ({"motors": MOTOR * 2}, "joint 'hip' has 2 actuators"),
        (
            {"root": ROOT.replace('<joint name="rooty" type="hinge" axis="0 1 0"/>', "")},
            "needs root joints slide x, slide z, hinge y",
        ),
        (
            {"root": ROOT.replace('axis="0 0 1"', 'axis="0 1 0"')},
            "found: slide(1 0 0), slide(0 1 0)",
        ),
        (
            {"leg_joints": '<joint name="hip" type="slide" axis="0 0 1" range="-1 1"/>'},
            "body 'leg' has a slide(0 0 1) joint, not a hinge",
        ),
        (
            {"leg_joints": '<joint name="hip" axis="0 -1 0"/>'},
            "joint 'hip' of body 'leg' has no range",
        ),
        ({"motors": MOTOR + '<motor joint="rootx"/>'}, "actuators on non-limb joints ['rootx']"),
        ({"text": "<mujoco><worldbody><body></mujoco>"}, "malformed MJCF"),
        ({"text": "<mujoco><worldbody/></mujoco>"}, "no robot body"),
    ],
)
def test_bad_user_files_get_one_clear_error(tmp_path, kwargs, problem):
    path = _write(tmp_path, **kwargs)
    with pytest.raises(MorphologyError) as err:
        load(path)
    message = str(err.value)
    assert message.startswith(f"{path}: ") and problem in message
    assert "\n" not in message


def test_two_robots_in_one_file_are_rejected(tmp_path):
    text = MINIMAL.format(root=ROOT, leg_joints=HINGE, motors=MOTOR).replace(
        "</worldbody>", '<body name="box"><geom type="box" size=".1 .1 .1"/></body></worldbody>'
    )
    with pytest.raises(MorphologyError, match=r"expected one robot under <worldbody>, found"):
        load(_write(tmp_path, text=text))


def test_unknown_name_lists_valid_names():
    with pytest.raises(MorphologyError) as err:
        load("walker_8_main")
    message = str(err.value)
    assert "unknown morphology 'walker_8_main'" in message and "did you mean" in message
    assert all(name in message for name in ROBOTS)


def test_missing_file(tmp_path):
    with pytest.raises(MorphologyError, match="MJCF file not found"):
        load(tmp_path / "nope.xml")
