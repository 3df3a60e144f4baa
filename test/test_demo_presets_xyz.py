"""The main job end to end (quick) on the presets of group ``xyz`` (``demo_runs.GROUPS``): one
``friction-demo --presets ...`` run shared by the module; every mode enabled or refused with its
reason, compensation helps where friction matters or the demo says why not, and each preset's
experiment run again at the same time on a saturated CPU gives the same bag, and its best mode's
tracking run again the same rows."""

from __future__ import annotations

import pytest
from demo_runs import (
    BEST,
    GROUPS,
    check_compensation_helps,
    check_every_preset_completes,
    check_reruns_identical,
    run_group,
)

pytestmark = [pytest.mark.ros, pytest.mark.slow]
GROUP = "xyz"


@pytest.fixture(scope="module")
def group_run(tmp_path_factory):
    # every preset's identification experiment again beside the demo, on a saturated CPU, then its
    # best mode's tracking run
    return run_group(tmp_path_factory, GROUP, rerun=GROUPS[GROUP], tracking=(BEST,))


def test_every_preset_completes_with_every_mode_enabled_or_refused(group_run):
    check_every_preset_completes(group_run.proc, group_run.out, GROUPS[GROUP])


def test_compensation_helps_where_friction_matters_and_is_reported_where_not(group_run):
    check_compensation_helps(group_run.out, GROUPS[GROUP])


def test_every_presets_experiment_and_best_tracking_run_give_the_same_bytes_under_load(group_run):
    check_reruns_identical(group_run)
    assert all(len(r["labels"]) == 1 for r in group_run.reruns.values()), group_run.reruns
