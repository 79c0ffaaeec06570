"""The ground truth in a lit room (lftransfer.sim.ground_truth with an ``[environment]``).

A tiny scene (48 x 36 view) of Fig. 4's block and cube in the ``probe`` scene's room. What it shows:
- the union and the real objects alone show the room behind them (no dark background), while the real objects'
  coverage is still that of the objects (Mitsuba's alpha counts the room as covered: it is measured apart);
- the synthetic objects alone show no room (their render is composited over the real one) and are lit by it;
- the cross term the room adds through the array is part of C_gt: the real objects alone stand behind the array's
  panel, so the union is brighter on them than they are alone.
"""

from __future__ import annotations

import numpy as np

from lftransfer.scenes import builtin_scene, load_scene, with_overrides
from lftransfer.sim.ground_truth import render_ground_truth


def test_01_the_room_in_the_ground_truth(variant):
    scene = with_overrides(load_scene(builtin_scene("probe")), view={"resolution": [48, 36]},
                           render={"gt_spp": 16})
    gt = render_ground_truth(scene, spp=16, use_cache=False)
    empty = (gt.alpha_real == 0) & (gt.alpha_synthetic == 0)
    assert empty.mean() > 0.5 and 0 < gt.alpha_real.mean() < 0.3
    assert gt.image[empty].min() > 0.05                           # the room behind everything
    assert gt.real[0][gt.alpha_real == 0].mean() > 0.05           # ... and behind the real objects alone
    assert np.all(gt.synthetic[0][gt.alpha_synthetic == 0] == 0)  # the synthetic render shows no room
    cube = gt.alpha_synthetic == 1
    assert gt.synthetic[0][cube].mean() > 0.1                     # lit by the room
    block = (gt.alpha_real == 1) & (gt.alpha_synthetic == 0)
    assert gt.image[block].mean() > 1.05 * gt.real.mean(axis=0)[block].mean()
