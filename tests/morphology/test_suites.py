import pytest

from solar_jax.morphology import ROBOTS, SUITES, MorphologyError, get_suite, load

# algorithm.md §1.
PAPER_SPLITS = {
    "walker++": (
        {"walker_2_main", "walker_4_main", "walker_5_main", "walker_7_main"},
        {"walker_3_main", "walker_6_main"},
        7,
    ),
    "humanoid++": (
        {
            f"humanoid_2d_{v}"
            for v in (
                "7_left_arm",
                "7_lower_arms",
                "7_right_leg",
                "8_left_knee",
                "8_right_knee",
                "9_full",
            )
        },
        {"humanoid_2d_7_left_leg", "humanoid_2d_7_right_arm"},
        9,
    ),
    "hopper++": ({"hopper_3", "hopper_4", "hopper_5"}, set(), 5),
    "cheetah++": (
        {n for n in ROBOTS if n.startswith("cheetah")}
        - {"cheetah_3_balanced", "cheetah_5_back", "cheetah_6_front"},
        {"cheetah_3_balanced", "cheetah_5_back", "cheetah_6_front"},
        7,
    ),
}


@pytest.mark.parametrize("name", list(PAPER_SPLITS))
def test_suite_splits_match_spec(name):
    train, held_out, n_max = PAPER_SPLITS[name]
    suite = get_suite(name)
    assert set(suite.train) == train and set(suite.held_out) == held_out
    assert suite.max_agents() == n_max
    assert suite.members == suite.train + suite.held_out


def test_whh_is_the_union_of_the_three_suites():
    whh = get_suite("whh++")
    parts = [PAPER_SPLITS[s] for s in ("walker++", "humanoid++", "hopper++")]
    assert set(whh.train) == set().union(*(p[0] for p in parts)) and len(whh.train) == 13
    assert set(whh.held_out) == set().union(*(p[1] for p in parts)) and len(whh.held_out) == 4
    assert whh.max_agents() == 9


@pytest.mark.parametrize("suite", list(SUITES))
def test_every_suite_member_loads(suite):
    for name in get_suite(suite).members:
        assert load(name).name == name
    assert len(set(get_suite(suite).members)) == len(get_suite(suite).members)


def test_single_robot_and_file_are_suites_of_one(tmp_path):
    suite = get_suite("walker_6_main")
    assert suite.train == ("walker_6_main",) and suite.held_out == ()
    path = tmp_path / "robot.xml"
    path.write_text(load("hopper_3").xml)
    assert get_suite(str(path)).train == (str(path),)
    assert get_suite(str(path)).max_agents() == 3


def test_unknown_suite_lists_valid_names():
    with pytest.raises(MorphologyError) as err:
        get_suite("walkers++")
    message = str(err.value)
    assert (
        "unknown suite or morphology 'walkers++'" in message and "did you mean walker++" in message
    )
    assert all(name in message for name in SUITES)
