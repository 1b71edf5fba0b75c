"""The live shell's inbox (issue 14, item 6): local inputs first, bus topics bounded and
taken in turn, one tick at a time."""

from __future__ import annotations

import threading

from humanpt.runtime.live import Inbox


def _drain(box: Inbox) -> list:
    out = []
    while (item := box.get(timeout=0)) is not None:
        out.append(item)
    return out


def test_local_inputs_overtake_a_bus_flood():
    box = Inbox({"console/command": 8})
    for i in range(10_000):
        box.put_bus("console/command", b"%d" % i)
    box.put_local(("local", "serial_rx", "bytes"))
    assert box.get(timeout=0) == ("local", "serial_rx", "bytes")
    rest = _drain(box)
    # Bounded: the 8 newest are kept, 9992 dropped and counted.
    assert [p for _, _, p in rest] == [b"%d" % i for i in range(9_992, 10_000)]
    assert box.dropped == {"console/command": 9_992}


def test_latest_wins_and_topics_take_turns():
    box = Inbox({"camera/image": 1, "controller/command": 64})
    for i in range(5):
        box.put_bus("camera/image", b"img%d" % i)
        box.put_bus("controller/command", b"cmd%d" % i)
    got = _drain(box)
    assert [p for _, t, p in got if t == "camera/image"] == [b"img4"]
    assert [p for _, t, p in got if t == "controller/command"] == [b"cmd%d" % i for i in range(5)]
    # Round robin: the image does not wait behind all five commands.
    assert [t for _, t, _ in got][:2] == ["camera/image", "controller/command"]


def test_a_core_that_fell_behind_gets_one_tick_not_a_burst():
    box = Inbox({})
    for _ in range(100):
        box.put_local(("tick", "tick", None))
    assert _drain(box) == [("tick", "tick", None)]
    box.put_local(("tick", "tick", None))
    assert _drain(box) == [("tick", "tick", None)]


def test_get_waits_for_a_put_from_another_thread():
    box = Inbox({})
    t = threading.Timer(0.05, box.put_bus, args=("x/y", b"late"))
    t.start()
    assert box.get(timeout=10) == ("bus", "x/y", b"late")
    t.join()
