"""Frames and a capture process in turns (lftransfer.transfer.share.TurnTaking): stopped while a frame renders,
then given its share of the last frame's time before the next, and only while it has a capture to work on."""

from __future__ import annotations

import time

import pytest

from lftransfer.transfer.share import TurnTaking


class _Process:
    def __init__(self) -> None:
        self.events: list[tuple[str, float]] = []
        self.working = True

    def pause(self) -> None:
        self.events.append(("pause", time.perf_counter()))

    def resume(self) -> None:
        self.events.append(("resume", time.perf_counter()))


def test_01_the_capture_process_is_stopped_exactly_while_a_frame_renders():
    p = _Process()
    turns = TurnTaking(p.pause, p.resume, lambda: p.working, share=0.25)
    with turns.rendering():
        assert [e for e, _ in p.events] == ["pause"]
        time.sleep(0.01)
    assert [e for e, _ in p.events] == ["pause", "resume"]
    with pytest.raises(RuntimeError):                    # an error in the frame still lets the process go on
        with turns.rendering():
            raise RuntimeError("the renderer failed")
    assert [e for e, _ in p.events][-1] == "resume"


@pytest.mark.parametrize("share", [0.25, 0.5])
def test_02_its_turn_is_its_share_of_the_last_frame(share):
    """After a frame of 0.2 s the next frame begins 0.2 * share / (1 - share) s later when the process has a
    capture to work on; at once when it has none (the negative control)."""
    p = _Process()
    turns = TurnTaking(p.pause, p.resume, lambda: p.working, share=share)
    with turns.rendering():
        time.sleep(0.2)
    owed = 0.2 * share / (1 - share)
    with turns.rendering():
        pass
    resumed, paused = p.events[1][1], p.events[2][1]
    assert owed <= paused - resumed <= owed + 0.03
    assert turns.waited_s == pytest.approx(owed, abs=0.02)
    # work done in between (the page waiting for news) counts towards the turn
    with turns.rendering():
        time.sleep(0.2)
    time.sleep(owed)
    start = time.perf_counter()
    with turns.rendering():
        pass
    assert time.perf_counter() - start < 0.02
    # nothing to capture: no wait
    p.working = False
    with turns.rendering():
        time.sleep(0.2)
    start = time.perf_counter()
    with turns.rendering():
        pass
    assert time.perf_counter() - start < 0.02


@pytest.mark.parametrize("share", [0.0, 1.0, -0.5])
def test_03_a_share_out_of_range_is_refused(share):
    with pytest.raises(ValueError, match="strictly between 0 and 1"):
        TurnTaking(lambda: None, lambda: None, lambda: True, share)
