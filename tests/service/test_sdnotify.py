"""sd_notify by hand: datagrams to NOTIFY_SOCKET (path or abstract), never blocking."""

import os

from svc import NotifyListener

from perchd.service.sdnotify import Notifier


def test_messages_reach_a_path_socket(tmp_path):
    listener = NotifyListener(tmp_path / "notify")
    n = Notifier({"NOTIFY_SOCKET": listener.address})
    assert n.ready("cf1: idle") and n.status("flying") and n.stopping()
    listener.drain(0.2)
    assert listener.messages == ["READY=1\nSTATUS=cf1: idle", "STATUS=flying", "STOPPING=1"]


def test_an_abstract_name_starting_with_at_is_sent_with_a_leading_nul():
    name = f"perchd-test-{os.getpid()}"
    listener = NotifyListener(abstract=name)
    assert Notifier({"NOTIFY_SOCKET": "@" + name}).send("WATCHDOG=1")
    assert listener.wait_for("WATCHDOG=1", 1.0) == "WATCHDOG=1"


def test_without_notify_socket_nothing_is_sent():
    n = Notifier({})
    assert not n.enabled and not n.ready() and not n.watchdog()


def test_a_vanished_socket_drops_the_message_instead_of_raising(tmp_path):
    n = Notifier({"NOTIFY_SOCKET": str(tmp_path / "gone")})
    assert n.enabled and n.send("READY=1") is False


def test_watchdog_pings_at_most_every_quarter_period(tmp_path):
    listener = NotifyListener(tmp_path / "notify")
    n = Notifier({"NOTIFY_SOCKET": listener.address, "WATCHDOG_USEC": "4000000"})
    assert n.watchdog_s == 4.0
    sent = [n.watchdog(now=t) for t in (0.0, 0.5, 0.99, 1.0, 1.5, 2.0)]
    assert sent == [True, False, False, True, False, True]


def test_a_watchdog_period_meant_for_another_pid_is_ignored():
    n = Notifier({"WATCHDOG_USEC": "5000000", "WATCHDOG_PID": str(os.getpid() + 1)})
    assert n.watchdog_s is None
