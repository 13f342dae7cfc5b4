"""ros/parameters.py: one table of parameters, and config/planner.yaml, the table in docs/PARAMETERS.md, the core's
options and GraspPlanner's defaults all agree with it."""
import inspect
import math
import re
from pathlib import Path

import pytest
import yaml

from humanoid_planner.core.pipeline.planner import GraspPlanner
from humanoid_planner.core.pipeline.problem import ProblemBuilder
from humanoid_planner.core.planners.common import PlannerOptions, option_ranges
from humanoid_planner.ros.parameters import PARAMETERS, SPECS, PlannerParameters, StartupError, declare_parameters

ROOT = Path(__file__).resolve().parents[3]


def test_planner_yaml_has_every_parameter_with_its_default_under_any_node():
    doc = yaml.safe_load((ROOT / "config" / "planner.yaml").read_text())
    assert list(doc) == ["/**"]
    assert doc["/**"]["ros__parameters"] == {s.name: s.default for s in PARAMETERS}


def test_the_documented_table_gives_every_parameter_its_default_and_range():
    text = (ROOT / "docs" / "PARAMETERS.md").read_text()
    rows = dict((m[0], (m[1], m[2])) for m in re.findall(r"^\| `(\w+)` \| ([^|]+) \| ([^|]+) \|", text, re.M)
                if m[0] in SPECS)
    assert set(rows) == set(SPECS)
    for s in PARAMETERS:
        default, rng = rows[s.name]
        want = ('`""`' if s.default == "" else f"`{s.default}`") if isinstance(s.default, str) else (
            str(s.default).lower() if isinstance(s.default, bool) else repr(s.default))
        assert (default, rng) == (want, s.range_text()), s.name


def test_planner_options_are_the_source_of_their_parameters():
    opts = PlannerOptions()
    for name, rng in option_ranges().items():
        assert SPECS[name].default == getattr(opts, name) and SPECS[name].range is rng
    assert PlannerParameters().options == opts
    assert {"collision_padding", "edge_resolution"} <= set(option_ranges())  # the checker's, in the options too
    own = set(inspect.signature(GraspPlanner.__init__).parameters) | set(inspect.signature(ProblemBuilder.__init__).parameters)
    assert not own & set(option_ranges()), "an option with a second default beside PlannerOptions"


def test_descriptors_are_one_per_parameter_with_range_and_read_only():
    descriptors = [s.descriptor() for s in PARAMETERS]
    assert len({id(d) for d in descriptors}) == len(descriptors)
    by_name = {d.name: d for d in descriptors}
    assert {n for n, d in by_name.items() if d.read_only} == {
        "robot", "robot_description", "robot_description_semantic", "planning_frame", "executor", "num_workers",
        "planning_processes", "max_triangles_per_message", "max_triangles_per_scene", "max_primitives_per_object", "max_grasps_per_object",
        "max_queued_plans", "max_queued_scene_updates"}
    assert all(d.description for d in descriptors)
    f = by_name["f_extend"].floating_point_range[0]
    assert (f.from_value, f.to_value) == (0.0, 1.0)
    i = by_name["num_workers"].integer_range[0]
    assert (i.from_value, i.to_value) == (0, 64)  # 0: one per core


@pytest.mark.parametrize("name,value", [("f_extend", 7.5), ("max_cycles", -5), ("default_timeout", -3.0),
                                        ("default_timeout", math.nan), ("edge_resolution", 0.0),
                                        ("tcp_step_pos", 0.0), ("collision_padding", -0.5)])
def test_bad_values_are_outside_the_table_ranges(name, value):
    with pytest.raises(ValueError, match=name):
        SPECS[name].range.check(name, value)
    SPECS[name].range.check(name, SPECS[name].default)


def test_with_values_replaces_node_and_planner_values():
    p = PlannerParameters().with_values({"default_timeout": 2.0, "f_extend": 0.5})
    assert p.default_timeout == 2.0 and p.options.f_extend == 0.5 and p.min_grasp_score == 0.001
    with pytest.raises(ValueError, match="f_extend"):
        PlannerOptions(f_extend=7.5).validate()


BAD_START = [("f_extend", 7.5), ("num_workers", -1), ("max_cycles", -5), ("default_timeout", -3.0),
             ("default_timeout", -1.0), ("default_timeout", math.nan), ("edge_resolution", 0.0),
             ("tcp_step_pos", 0.0), ("collision_padding", -0.5), ("executor", "multi")]


def test_every_bad_start_value_is_one_line_naming_it(ros_domain_id):
    """What planner_node prints before it exits 1 (test_live_node runs two of these as processes)."""
    import rclpy
    from rclpy.context import Context
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    context = Context()
    rclpy.init(context=context, domain_id=ros_domain_id)
    try:
        for name, value in BAD_START:
            node = Node("bad_start", context=context, parameter_overrides=[Parameter(name, value=value)],
                        start_parameter_services=False)
            try:
                with pytest.raises(StartupError) as refused:
                    declare_parameters(node)
            finally:
                node.destroy_node()
            text = str(refused.value)
            assert "\n" not in text and text.startswith(f"parameter {name}=") and "refused: must be" in text, text
    finally:
        context.try_shutdown()
