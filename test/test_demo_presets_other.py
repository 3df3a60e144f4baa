"""The main job end to end (quick) on the presets of group ``other`` (``demo_runs.GROUPS``): one
``friction-demo --presets ...`` run shared by the module; every mode enabled or refused with its
reason, and compensation helps where friction matters or the demo says why not; the longest
experiment of the group, again beside it on a saturated CPU, gives the same bag."""

from __future__ import annotations

import json

import pytest
from demo_runs import (
    GROUPS,
    LONGEST_EXPERIMENT,
    check_compensation_helps,
    check_every_preset_completes,
    check_reruns_identical,
    run_group,
)

from friction_ros.core.bag import content_digest

pytestmark = [pytest.mark.ros, pytest.mark.slow]
GROUP = "other"


@pytest.fixture(scope="module")
def group_run(tmp_path_factory):
    return run_group(tmp_path_factory, GROUP, rerun=(LONGEST_EXPERIMENT,))


def test_every_preset_completes_with_every_mode_enabled_or_refused(group_run):
    check_every_preset_completes(group_run.proc, group_run.out, GROUPS[GROUP])


def test_compensation_helps_where_friction_matters_and_is_reported_where_not(group_run):
    check_compensation_helps(group_run.out, GROUPS[GROUP])


def test_the_longest_experiment_again_under_load_gives_the_same_bag(group_run):
    check_reruns_identical(group_run)
    states = {}
    for name in GROUPS[GROUP]:
        bag = json.loads((group_run.out / name / "demo_summary.json").read_text())["bag"]
        states[name] = content_digest(bag, ["/joint_states"])[1]["/joint_states"]
    assert list(group_run.reruns) == [LONGEST_EXPERIMENT] == [max(states, key=states.get)], states
