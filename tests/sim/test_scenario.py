"""Scenario TOML is parsed strictly: unknown keys, wrong types, missing files are one-line errors."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from autonomy.common.errors import InputError
from autonomy.localization.cgr import CGRConfig
from sim.config import apply_overrides, parse_override
from sim.scenario import SCENARIOS_DIR, Scenario, list_scenarios, load_scenario


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "s.toml"
    p.write_text(text)
    return p


BASE = 'name = "t"\n[map]\nname = "small_floor"\n'


def test_every_shipped_scenario_parses() -> None:
    items = list_scenarios()
    assert items, "no scenarios shipped"
    from sim.experiments.kinds import load_experiment

    for path, desc in items:
        exp, cfg = load_experiment(path)
        assert isinstance(cfg, exp.config_type)
        if exp.kind == "mission":
            assert isinstance(cfg, Scenario)
        assert cfg.name and desc, f"{path.name} has no name or description"


def test_kinds_are_checked(tmp_path: Path) -> None:
    from sim.experiments.kinds import load_experiment

    p = tmp_path / "k.toml"
    p.write_text('kind = "teleport"\nname = "x"\n')
    with pytest.raises(InputError, match="unknown experiment kind 'teleport'"):
        load_experiment(p)
    p.write_text('kind = "mapping_wall"\nname = "x"\n')
    with pytest.raises(InputError, match="not a mission scenario"):
        load_scenario(p)


def test_defaults_are_the_papers_and_design_values(tmp_path: Path) -> None:
    scn = load_scenario(_write(tmp_path, BASE))
    assert scn.kinect.intrinsics.width == 640 and scn.kinect.intrinsics.fx == 580.0
    assert scn.kinect.mount.height_m == 0.7 and scn.kinect.mount.forward_m == 0.22
    assert scn.robot.max_speed_mps == 0.75 and scn.robot.max_angular_rad_s == 1.5
    assert scn.world.wall_height_m == 2.5 and scn.world.wall_thickness_m == 0.02
    assert scn.odometry.translation_noise == 0.2


@pytest.mark.parametrize(
    "text, pattern",
    [
        (BASE + "[robot]\nmax_sped_mps = 1.0\n", r"s\.toml: unknown key 'robot\.max_sped_mps' \(expected one of: "),
        (BASE + "[robot]\nmax_speed_mps = \"fast\"\n", r"key 'robot\.max_speed_mps' expected a number, got string 'fast'"),
        (BASE + "[kinect.noise]\nshadows = 1\n", r"key 'kinect\.noise\.shadows' expected true or false"),
        (BASE + "[kinect.intrinsics]\nwidth = 640.5\n", r"key 'kinect\.intrinsics\.width' expected an integer"),
        (BASE + "[robot]\nradius_m = -1.0\n", r"s\.toml: robot\.radius_m: expected a positive number"),
        ('name = "t"\n[map]\nname = "nope"\n', r"key 'map\.name': no building 'nope'"),
        ('name = "t"\n[map]\nvectormap = "x.txt"\nnavgraph = "y.json"\n', r"key 'map\.vectormap': file not found"),
        ("[map]\nname = \"small_floor\"\n", r"missing key 'name'"),
        (BASE + "[[actors.furniture]]\nkind = \"sofa\"\n", r"furniture kind 'sofa'"),
        (BASE + "[[actors.people]]\nroute = [[0, 0]]\n", r"at least two"),
        (BASE + "[mission]\nkind = \"dance\"\n", r"mission\.kind 'dance'"),
        ("seed = [1]\n" + BASE, r"key 'seed' expected an integer, got an array"),
        (BASE + "seed = 3\n", r"unknown key 'map\.seed'"),
        ("name = \n", r"s\.toml: invalid TOML"),
        (BASE + "[avoidance.near_field]\nmin_invalid_fraction = 1.5\n", r"s\.toml: avoidance\.near_field\.min_invalid_fraction: expected a number in"),
        (BASE + "[report]\ncheckpoint_s = -1.0\n", r"s\.toml: report\.checkpoint_s: expected a number of seconds >= 0"),
        (BASE + "[avoidance.near_field]\nband_max_depth_m = 0.5\n", r"s\.toml: avoidance\.near_field: no image row sees the floor"),
        (BASE.replace("[map]", "[map]\nirregular = false"), r"s\.toml: map\.irregular: only a generated building"),
    ],
)
def test_bad_scenarios_name_file_key_and_expectation(tmp_path: Path, text: str, pattern: str) -> None:
    with pytest.raises(InputError, match=pattern) as ei:
        load_scenario(_write(tmp_path, text))
    assert "\n" not in str(ei.value)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="scenario file not found"):
        load_scenario(tmp_path / "none.toml")


def test_overrides_go_through_the_same_checks(tmp_path: Path) -> None:
    p = _write(tmp_path, BASE)
    scn = load_scenario(p, ["robot.max_speed_mps=0.5", "kinect.noise.shadows=false", "mission.waypoints=[1, 2]"])
    assert scn.robot.max_speed_mps == 0.5 and scn.kinect.noise.shadows is False and scn.mission.waypoints == (1, 2)
    with pytest.raises(InputError, match="unknown key 'robot.speed'"):
        load_scenario(p, ["robot.speed=1"])
    with pytest.raises(InputError, match="expected KEY=VALUE"):
        load_scenario(p, ["robot.max_speed_mps"])
    with pytest.raises(InputError, match="expected a number, got string 'abc'"):
        load_scenario(p, ["robot.max_speed_mps=abc"])


@given(st.text(alphabet="abcdefgh._=[] 0123456789\"'", max_size=30))
def test_override_parser_never_crashes(text: str) -> None:
    try:
        path, _ = parse_override(text)
        apply_overrides({}, [text])
        assert all(path)
    except InputError:
        pass


def test_shipped_scenarios_dir_exists() -> None:
    assert (SCENARIOS_DIR / "demo.toml").is_file()


def test_the_robot_radius_has_one_source() -> None:
    """The stack avoids with the simulated body's radius; setting it twice is an error."""

    scn = load_scenario(SCENARIOS_DIR / "demo.toml", ["robot.radius_m=0.25"])
    assert scn.avoidance.robot_radius_m == 0.25 and scn.stack_config().avoidance.robot_radius_m == 0.25
    with pytest.raises(InputError, match=r"avoidance\.robot_radius_m.*robot\.radius_m"):
        load_scenario(SCENARIOS_DIR / "demo.toml", ["avoidance.robot_radius_m=0.25"])
    cam = load_scenario(SCENARIOS_DIR / "demo.toml", ["kinect.noise.max_range_m=3.5"]).stack_config().camera
    assert cam.max_range_m == 3.5 and cam.fov_h_rad == scn.kinect.intrinsics.fov_h_rad
    with pytest.raises(InputError, match=r"^\S+demo\.toml: kinect\.noise\.min_range_m: expected a positive"):
        load_scenario(SCENARIOS_DIR / "demo.toml", ["kinect.noise.min_range_m=0"])


def test_an_avoidance_radius_other_than_the_body_is_refused_everywhere() -> None:
    from autonomy.navigation.avoidance import AvoidanceConfig
    from sim.envs.config import EnvConfig
    from sim.simulator.robot import RobotConfig, avoidance_for_body

    small = AvoidanceConfig(robot_radius_m=0.2)
    with pytest.raises(InputError, match=r"^DepthNav: avoidance\.robot_radius_m \(0\.2\) differs from robot\.radius_m \(0\.3\)"):
        EnvConfig(avoidance=small)
    assert EnvConfig(avoidance=small, robot=RobotConfig(radius_m=0.2)).avoidance.robot_radius_m == 0.2
    # Left at its default, the avoidance takes the body's radius.
    assert avoidance_for_body(AvoidanceConfig(), RobotConfig(radius_m=0.4), "x").robot_radius_m == 0.4


def test_a_generated_building_is_irregular_unless_asked_square(tmp_path: Path) -> None:
    from sim.simulator.irregular import Irregularity

    irregular = load_scenario(_write(tmp_path, 'name = "t"\n[map]\ngenerate_seed = 3\n'))
    assert irregular.map.building_config().irregularity == Irregularity()
    square = load_scenario(_write(tmp_path, 'name = "t"\n[map]\ngenerate_seed = 3\nirregular = false\n'))
    assert square.map.building_config().irregularity == Irregularity.none()


def test_a_calibrated_motion_model_is_the_odometrys() -> None:
    """calibrated_motion: CGR's motion noise follows the simulated odometry; CGR's alphas
    cannot be set beside it. Off (the default): the alphas as given."""
    on = ["localization.calibrated_motion=true", "odometry.rotation_noise=0.07", "odometry.rotation_per_translation_rad_per_m=0.01"]
    scn = load_scenario(SCENARIOS_DIR / "demo.toml", on)
    cgr = scn.stack_config().localization.cgr
    assert (cgr.alpha1, cgr.alpha2_rad_per_m, cgr.alpha3) == (0.07, 0.01, scn.odometry.translation_noise)
    with pytest.raises(InputError, match="localization.cgr.alpha1 is set while localization.calibrated_motion = true"):
        load_scenario(SCENARIOS_DIR / "demo.toml", ["localization.calibrated_motion=true", "localization.cgr.alpha1=0.2"])
    own = load_scenario(SCENARIOS_DIR / "demo.toml", ["localization.cgr.alpha1=0.2"])
    assert own.stack_config().localization.cgr.alpha1 == 0.2
    assert own.stack_config().localization.cgr.alpha3 == CGRConfig().alpha3
    assert load_scenario(SCENARIOS_DIR / "demo.toml").stack_config().localization.cgr == CGRConfig()


@given(st.lists(st.floats(allow_nan=False, allow_infinity=False, width=32), min_size=1, max_size=5))
def test_parse_floats_reads_what_it_is_given_and_counts(values: list[float]) -> None:
    """Command-line number lists: the values back, or one line naming the option."""
    from sim.config import parse_floats

    text = ",".join(repr(v) for v in values)
    if len(values) == 3:
        assert parse_floats(text, "--pose", 3, "x,y,theta (metres, radians)", "1,2,0") == tuple(values)
    else:
        with pytest.raises(InputError, match=r"^--pose .*: expected x,y,theta \(metres, radians\), e.g. 1,2,0$"):
            parse_floats(text, "--pose", 3, "x,y,theta (metres, radians)", "1,2,0")
