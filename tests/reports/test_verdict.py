"""A run's verdict (lftransfer.reports.verdict): one line that reads the headline, its confidence and the floor."""

from __future__ import annotations

from lftransfer.reports.verdict import verdict

FLOOR = {"floor": 0.103, "transfer": 0.118, "transfer_over_floor": 0.118 / 0.103}
RUN = {"cross_transfer_rel_error": 0.166, "cross_gt_noise_rel": 0.233, "cross_term_rel_size": 0.019,
       "fidelity_floor": FLOOR, "undefined_metrics": {}}


def test_a_floor_judges_a_noisy_run():
    """The floor's comparison takes the reference's noise off both sides, so a run whose raw error is mostly noise
    is still judged against what the rig allows (Fig. 4 at --quick: 1.15x)."""
    v = verdict(RUN)
    assert v["judged"] and v["transfer_over_floor"] == FLOOR["transfer_over_floor"]
    assert v["reading"].startswith("within 1.15x of what this rig allows") and "0.23" in v["reading"]
    close = {**FLOOR, "transfer": 0.105, "transfer_over_floor": 0.105 / 0.103}
    assert verdict({**RUN, "fidelity_floor": close})["reading"].startswith("at what this rig allows")


def test_a_negligible_cross_term_is_too_small_to_judge():
    """A cross term of 0.5 % of the image is said to be too small to judge, whatever its error (negative control:
    at 2 % the same run is judged)."""
    v = verdict({**RUN, "cross_term_rel_size": 0.005})
    assert not v["judged"] and "0.5 % of the image" in v["reading"] and "too small to judge" in v["reading"]
    assert verdict({**RUN, "cross_term_rel_size": 0.02})["judged"]


def test_without_a_floor_only_a_quiet_enough_reference_judges():
    """No floor: a reference noisier than half the error is not judged and says what would judge it; a quiet one
    is, with its noise as the error's confidence; an unverified run says why."""
    noisy = verdict({**RUN, "fidelity_floor": None, "undefined_metrics": {"fidelity_floor": "--no-floor"}})
    assert not noisy["judged"] and "--quiet-reference" in noisy["reading"]
    quiet = verdict({**RUN, "fidelity_floor": None, "cross_gt_noise_rel": 0.04,
                     "undefined_metrics": {"fidelity_floor": "not asked for (--no-floor)"}})
    assert quiet["judged"] and quiet["reading"].startswith("cross error 0.166 +- 0.04")
    assert "--no-floor" in quiet["reading"]
    blind = verdict({"cross_transfer_rel_error": None, "verification": "none: the hardware rig's real scene is not "
                                                                       "known to lftransfer"})
    assert not blind["judged"] and "hardware rig" in blind["reading"]
